// The command groups of inspectctl, one file each (cmd_*.cc), registered by main.cc. Each adds
// its CLI11 subcommands to the app and their handlers to the context. A new group is a new
// cmd_*.cc, its declaration here and one registration line in main.cc.
#pragma once

#include <CLI/CLI.hpp>

#include "client_cli/cli_context.h"

namespace inspection::client::cli {

void RegisterStatusCommands(CLI::App& app, CliContext& context);       // status, reset
void RegisterScanCommand(CLI::App& app, CliContext& context);          // scan
void RegisterReconstructCommand(CLI::App& app, CliContext& context);   // reconstruct
void RegisterJobCommands(CLI::App& app, CliContext& context);          // jobs, watch, cancel, delete, pin, download
void RegisterCalibrationCommands(CLI::App& app, CliContext& context);  // calibrate, calibration show|list
void RegisterSpecimenCommands(CLI::App& app, CliContext& context);     // specimen list|set
void RegisterRecipeCommands(CLI::App& app, CliContext& context);       // recipe create|update|get|list|delete
void RegisterResultCommands(CLI::App& app, CliContext& context);       // results list|watch
void RegisterStudyCommands(CLI::App& app, CliContext& context);        // study type1|list|show
void RegisterVerifyCommand(CLI::App& app, CliContext& context);        // verify

}  // namespace inspection::client::cli
