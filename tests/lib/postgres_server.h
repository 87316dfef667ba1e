// A private PostgreSQL 15 server for tests: initdb in a temporary folder, started on a free
// loopback port with its socket in that folder, stopped and removed at the end. PostgreSQL
// refuses to run as root, so as root the server runs as the `postgres` user the Debian package
// creates. Password authentication (scram-sha-256) with the password `Password()`, so tests
// exercise the password path. Missing binaries are a test failure, not a skip: the suite needs
// Debian's postgresql package (deploy/dev.sh installs it).
// ctest runs every test case in a process of its own, and each process that needs PostgreSQL
// starts its own server. initdb is the costly part (a few bootstrap backends: about 2 s of a CI
// core per process), so it runs once per machine and server user: the first process makes a
// template cluster (/tmp/inspect-pg-template-<uid>-<binary stamp>, made under a lock and
// renamed into place whole) and every process copies it into its own folder. Every cluster has
// the same superuser and password, so a copy is what initdb would have made. When the template
// cannot be made or copied, or a copy does not start, the process runs initdb itself.
#pragma once

#include <gtest/gtest.h>
#include <libpq-fe.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <pwd.h>
#include <sys/file.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace inspection::testing {

class PostgresServer {
 public:
  static constexpr const char* kBinDir = "/usr/lib/postgresql/15/bin";

  PostgresServer() {
    namespace fs = std::filesystem;
    if (!fs::exists(fs::path(kBinDir) / "initdb")) {
      ADD_FAILURE() << "PostgreSQL 15 is not installed (" << kBinDir << "/initdb): apt-get install postgresql";
      return;
    }
    char tmpl[] = "/tmp/inspect-pg-XXXXXX";
    if (!mkdtemp(tmpl)) {
      ADD_FAILURE() << "mkdtemp failed";
      return;
    }
    dir_ = tmpl;
    port_ = FreePort();
    run_as_ = geteuid() == 0 ? "runuser -u postgres -- " : "";
    if (geteuid() == 0) {
      struct passwd* pw = getpwnam("postgres");
      if (!pw) {
        ADD_FAILURE() << "no postgres user (Debian's postgresql package creates it)";
        return;
      }
      if (chown(dir_.c_str(), pw->pw_uid, pw->pw_gid) != 0) {
        ADD_FAILURE() << "chown " << dir_;
        return;
      }
    }
    {
      std::ofstream(dir_ + "/pw") << Password() << "\n";
    }
    if (geteuid() == 0) Run("chown postgres " + dir_ + "/pw");
    const bool copied = CopyTemplate(dir_ + "/data");
    if (!copied && !InitDb(dir_ + "/data", dir_ + "/pw", dir_ + "/initdb.log")) {
      ADD_FAILURE() << "initdb failed: see " << dir_ << "/initdb.log";
      return;
    }
    bool up = Start("/pg_ctl.log");
    if (!up && copied) {  // a damaged template (a /tmp cleaner?): this process's own initdb instead
      std::error_code ec;
      std::filesystem::remove_all(dir_ + "/data", ec);
      up = InitDb(dir_ + "/data", dir_ + "/pw", dir_ + "/initdb.log") && Start("/pg_ctl.log");
    }
    if (!up) {
      ADD_FAILURE() << "pg_ctl start failed: see " << dir_ << "/server.log";
      return;
    }
    started_ = true;
  }
  ~PostgresServer() {
    if (started_) Run(run_as_ + std::string(kBinDir) + "/pg_ctl -D " + dir_ + "/data -m immediate stop > /dev/null 2>&1");
    if (!dir_.empty()) {
      std::error_code ec;
      std::filesystem::remove_all(dir_, ec);
    }
  }
  PostgresServer(const PostgresServer&) = delete;
  PostgresServer& operator=(const PostgresServer&) = delete;

  bool started() const { return started_; }
  int port() const { return port_; }
  static std::string Password() { return "s3cret-for-tests"; }
  // A URL without the password (it comes from a file or PGPASSWORD in the product).
  std::string Url(const std::string& database = "postgres") const {
    return "postgresql://postgres@127.0.0.1:" + std::to_string(port_) + "/" + database;
  }
  // A file holding the password, as database_password_file.
  std::string PasswordFile() const { return dir_ + "/pw"; }

  // Creates an empty database and returns its URL: every test gets its own.
  std::string CreateDatabase(const std::string& name) const {
    const std::string conninfo = Url() + "?password=" + Password();
    PGconn* c = PQconnectdb(conninfo.c_str());
    EXPECT_EQ(PQstatus(c), CONNECTION_OK) << PQerrorMessage(c);
    PGresult* r = PQexec(c, ("DROP DATABASE IF EXISTS " + name).c_str());
    PQclear(r);
    r = PQexec(c, ("CREATE DATABASE " + name).c_str());
    EXPECT_EQ(PQresultStatus(r), PGRES_COMMAND_OK) << PQerrorMessage(c);
    PQclear(r);
    PQfinish(c);
    return Url(name);
  }
  // Runs one SQL statement in `database` (for tests that tamper with the schema).
  void Execute(const std::string& database, const std::string& sql) const {
    const std::string conninfo = Url(database) + "?password=" + Password();
    PGconn* c = PQconnectdb(conninfo.c_str());
    ASSERT_EQ(PQstatus(c), CONNECTION_OK) << PQerrorMessage(c);
    PGresult* r = PQexec(c, sql.c_str());
    EXPECT_TRUE(PQresultStatus(r) == PGRES_COMMAND_OK || PQresultStatus(r) == PGRES_TUPLES_OK) << PQerrorMessage(c);
    PQclear(r);
    PQfinish(c);
  }
  // Stops and starts the server (as a restart of the database host).
  bool Stop() const { return Run(run_as_ + std::string(kBinDir) + "/pg_ctl -D " + dir_ + "/data -w -m fast stop > /dev/null 2>&1"); }
  bool Start(const std::string& log = "") const {
    return Run(run_as_ + std::string(kBinDir) + "/pg_ctl -D " + dir_ + "/data -w -l " + dir_ + "/server.log -o \"-k " +
               dir_ + " -p " + std::to_string(port_) + " -c listen_addresses=127.0.0.1 -c fsync=off\" start > " +
               (log.empty() ? std::string("/dev/null") : dir_ + log) + " 2>&1");
  }

 private:
  static bool Run(const std::string& cmd) { return std::system(cmd.c_str()) == 0; }
  bool InitDb(const std::string& data, const std::string& pwfile, const std::string& log) const {
    return Run(run_as_ + std::string(kBinDir) + "/initdb -D " + data + " -U postgres -A scram-sha-256 --pwfile=" + pwfile +
               " --no-sync > " + log + " 2>&1");
  }
  // Copies the template cluster (made first if no process made it yet) to `data`; false when
  // there is none to copy, and then `data` does not exist.
  bool CopyTemplate(const std::string& data) const {
    namespace fs = std::filesystem;
    struct stat st {};
    if (stat((std::string(kBinDir) + "/postgres").c_str(), &st) != 0) return false;
    uid_t server_uid = geteuid();
    gid_t server_gid = getegid();
    if (geteuid() == 0) {
      struct passwd* pw = getpwnam("postgres");
      if (!pw) return false;
      server_uid = pw->pw_uid;
      server_gid = pw->pw_gid;
    }
    // Another PostgreSQL build (an upgrade of the package) gets a template of its own.
    const std::string base = "/tmp/inspect-pg-template-" + std::to_string(server_uid) + "-" +
                             std::to_string(static_cast<long long>(st.st_mtime)) + "-" +
                             std::to_string(static_cast<long long>(st.st_size));
    const std::string ready = base + "/data";
    std::error_code ec;
    if (!fs::exists(ready + "/PG_VERSION", ec)) {
      const int lock = open((base + ".lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
      if (lock < 0) return false;
      flock(lock, LOCK_EX);  // one process makes it; the others wait for it here
      bool ok = fs::exists(ready + "/PG_VERSION", ec);
      if (!ok) {
        const std::string work = base + ".making";
        fs::remove_all(work, ec);
        ok = fs::create_directory(work, ec) && chown(work.c_str(), server_uid, server_gid) == 0;
        if (ok) {
          std::ofstream(work + "/pw") << Password() << "\n";
          ok = chown((work + "/pw").c_str(), server_uid, server_gid) == 0 &&
               InitDb(work + "/data", work + "/pw", work + "/initdb.log");
        }
        fs::remove_all(base, ec);
        if (ok) {
          fs::rename(work, base, ec);  // whole or not at all: a crash leaves no half template
          ok = !ec;
        }
        if (!ok) fs::remove_all(work, ec);
      }
      flock(lock, LOCK_UN);
      close(lock);
      if (!ok) return false;
    }
    // cp -a keeps the owner (postgres) and the 0700 mode the server insists on.
    if (Run(run_as_ + "cp -a " + ready + " " + data + " > /dev/null 2>&1")) return true;
    fs::remove_all(data, ec);
    return false;
  }
  static int FreePort() {
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    socklen_t len = sizeof(a);
    int port = 0;
    if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0 &&
        getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0) {
      port = ntohs(a.sin_port);
    }
    close(fd);
    return port;
  }

  std::string dir_;
  std::string run_as_;
  int port_ = 0;
  bool started_ = false;
};

}  // namespace inspection::testing
