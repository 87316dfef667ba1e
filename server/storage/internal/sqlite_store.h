// The SQLite backend of DataStore (internal to server/storage: callers use DataStore::Open).
#pragma once

#include <filesystem>
#include <memory>

#include "server/storage/data_store.h"

namespace inspection {

// <data_dir>/inspection.db, created and migrated to kStoreSchemaVersion.
StatusOr<std::unique_ptr<DataStore>> OpenSqliteStore(const std::filesystem::path& data_dir);

}  // namespace inspection
