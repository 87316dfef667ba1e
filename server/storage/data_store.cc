// DataStore::Open: the data directory's folders, and the metadata backend the options name.
#include "server/storage/data_store.h"

#include <libpq-fe.h>

#include <fstream>
#include <random>
#include <regex>

#include "server/storage/internal/postgres_store.h"
#include "server/storage/internal/sqlite_store.h"

namespace inspection {
namespace fs = std::filesystem;

std::string NewId(const std::string& prefix) {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  char buf[17];
  std::snprintf(buf, sizeof(buf), "%016llx", static_cast<unsigned long long>(rng()));
  return prefix + "-" + buf;
}

std::string RedactDatabaseUrl(const std::string& url) {
  // URL form: scheme://user:password@host -> scheme://user:***@host; key=value form: password=***.
  static const std::regex url_password(R"(^([a-z]+://[^:/@?]*):[^@/?]*@)");
  static const std::regex kv_password(R"((^|\s)password\s*=\s*('[^']*'|\S+))");
  static const std::regex query_password(R"(([?&]password=)[^&]*)");
  std::string out = std::regex_replace(url, url_password, "$1:***@");
  out = std::regex_replace(out, kv_password, "$1password=***");
  return std::regex_replace(out, query_password, "$1***");
}

std::shared_ptr<OwnedFolder> DataStore::NewUploadFolder(const std::string& prefix) {
  const fs::path path = uploads_dir() / NewId(prefix);
  return std::make_shared<OwnedFolder>(path, live_work_folders_.Hold(path));
}

Status DataStore::PrepareFolders(bool empty_work_areas) {
  std::error_code ec;
  for (const fs::path& d : {data_dir_, scans_dir(), artifacts_dir(), calibrations_dir(), uploads_dir(), tmp_dir()}) {
    fs::create_directories(d, ec);
    if (ec) return Status::FailedPrecondition("data dir: cannot create " + d.string() + ": " + ec.message());
  }
  // Work areas hold only unfinished writes: whatever is there is from a previous run that stopped.
  // Not where several replicas share the folder (PostgreSQL): the others' uploads are there.
  if (!empty_work_areas) return Status::Ok();
  for (const fs::path& d : {uploads_dir(), tmp_dir()}) {
    for (const auto& entry : fs::directory_iterator(d, ec)) fs::remove_all(entry.path(), ec);
  }
  return Status::Ok();
}

namespace {

bool IsPostgresUrl(const std::string& url) {
  return url.rfind("postgresql://", 0) == 0 || url.rfind("postgres://", 0) == 0 || url.rfind("host=", 0) == 0 ||
         url.rfind("dbname=", 0) == 0;
}

// libpq's own parser decides what a valid connection string is; its message names the problem.
Status ValidateConninfo(const std::string& url) {
  char* error = nullptr;
  PQconninfoOption* options = PQconninfoParse(url.c_str(), &error);
  if (options == nullptr) {
    std::string message = error ? error : "out of memory";
    PQfreemem(error);
    while (!message.empty() && (message.back() == '\n' || message.back() == ' ')) message.pop_back();
    return Status::InvalidArgument("database: '" + RedactDatabaseUrl(url) + "' is not a PostgreSQL URL: " + message);
  }
  // libpq checks the port only when it connects; a typo there is a configuration error, not an
  // unreachable server.
  std::string bad_port;
  for (PQconninfoOption* o = options; o->keyword != nullptr; ++o) {
    if (std::string(o->keyword) == "port" && o->val != nullptr) {
      const std::string port = o->val;
      if (port.empty() || port.find_first_not_of("0123456789,") != std::string::npos) bad_port = port;
    }
  }
  PQconninfoFree(options);
  if (!bad_port.empty()) {
    return Status::InvalidArgument("database: '" + RedactDatabaseUrl(url) + "' has port '" + bad_port +
                                   "', not a number");
  }
  return Status::Ok();
}

StatusOr<std::string> ReadPassword(const fs::path& file) {
  std::ifstream in(file);
  if (!in) return Status::InvalidArgument("database_password_file: cannot read " + file.string());
  std::string line;
  std::getline(in, line);
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
  if (line.empty()) return Status::InvalidArgument("database_password_file: " + file.string() + " is empty");
  return line;
}

}  // namespace

Status ValidateDatabaseOptions(const DatabaseOptions& database) {
  const std::string& url = database.url;
  const bool postgres = IsPostgresUrl(url);
  if (!postgres && !url.empty() && url != "sqlite") {
    return Status::InvalidArgument("database: '" + RedactDatabaseUrl(url) +
                                   "' is neither \"sqlite\" nor a postgresql:// URL");
  }
  if (!postgres && !database.password_file.empty()) {
    return Status::InvalidArgument("database_password_file: set, but the database is SQLite");
  }
  if (postgres) INSPECT_RETURN_IF_ERROR(ValidateConninfo(url));
  return Status::Ok();
}

StatusOr<std::unique_ptr<DataStore>> DataStore::Open(const fs::path& data_dir, const DatabaseOptions& database) {
  INSPECT_RETURN_IF_ERROR(ValidateDatabaseOptions(database));
  const std::string& url = database.url;
  const bool postgres = IsPostgresUrl(url);
  std::string password;
  if (postgres && !database.password_file.empty()) {
    INSPECT_ASSIGN_OR_RETURN(password, ReadPassword(database.password_file));
  }
  std::error_code ec;
  fs::create_directories(data_dir, ec);
  if (ec) return Status::FailedPrecondition("data dir: cannot create " + data_dir.string() + ": " + ec.message());
  std::unique_ptr<DataStore> store;
  if (postgres) {
    INSPECT_ASSIGN_OR_RETURN(store, OpenPostgresStore(data_dir, url, password));
  } else {
    INSPECT_ASSIGN_OR_RETURN(store, OpenSqliteStore(data_dir));
  }
  INSPECT_RETURN_IF_ERROR(store->PrepareFolders(/*empty_work_areas=*/!postgres));
  return store;
}

}  // namespace inspection
