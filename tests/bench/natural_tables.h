// The natural-scene evaluation (docs/reconstruction.md "Depth post-processing and natural scenes"): focal stacks rendered with ground truth
// (devices/sim/natural_scene.h), every focus measure, window, interpolation, threshold and
// post-processing scored against the truth and against focus-stack when it is installed.
// Printed by natural-evaluate and by inspect-evaluate --natural.
#pragma once

namespace inspection {

// argv as natural-evaluate's (argv[0] the program name; --help lists the options). Prints to
// stdout; returns the process exit status (0 ok, 2 usage, 1 failure).
int RunNaturalEvaluation(int argc, char** argv);

}  // namespace inspection
