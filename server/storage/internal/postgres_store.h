// The PostgreSQL backend of DataStore (internal to server/storage: callers use DataStore::Open).
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "server/storage/data_store.h"

namespace inspection {

// Connects with libpq to `conninfo` (a URL or key=value string, already validated), with the
// password if not empty, and migrates the schema to kStoreSchemaVersion (one transaction per
// version, serialised across replicas by an advisory lock). UNAVAILABLE when the server cannot
// be reached.
StatusOr<std::unique_ptr<DataStore>> OpenPostgresStore(const std::filesystem::path& data_dir,
                                                       const std::string& conninfo, const std::string& password);

}  // namespace inspection
