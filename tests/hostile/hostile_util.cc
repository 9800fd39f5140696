#include "hostile_util.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

namespace u3mscan::hostile {

namespace {

struct Started {
  pid_t pid = -1;
  fs::path log;
};

Started Start(const RunSpec& run) {
  fs::create_directories(run.tmp_dir);
  Started started;
  started.log = run.tmp_dir.parent_path() / (run.tmp_dir.filename().string() + ".log");
  std::vector<std::string> argv_strings{U3MSCAN_EXE};
  argv_strings.insert(argv_strings.end(), run.args.begin(), run.args.end());
  std::vector<char*> argv;
  for (std::string& s : argv_strings) argv.push_back(s.data());
  argv.push_back(nullptr);
  const bool limit = std::getenv("U3MSCAN_HOSTILE_NO_RLIMIT") == nullptr;
  started.pid = ::fork();
  if (started.pid == 0) {
    const int fd = ::open(started.log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) ::_exit(127);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::setenv("TMPDIR", run.tmp_dir.c_str(), 1);
    if (limit) {
      const rlimit memory{kMemoryLimitBytes, kMemoryLimitBytes};
      ::setrlimit(RLIMIT_AS, &memory);
      const rlimit cpu{kCpuLimitSeconds, kCpuLimitSeconds};
      ::setrlimit(RLIMIT_CPU, &cpu);
    }
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return started;
}

RunResult Wait(const Started& started) {
  RunResult result;
  int status = 0;
  if (started.pid < 0 || ::waitpid(started.pid, &status, 0) != started.pid) {
    result.output = "could not run " + std::string(U3MSCAN_EXE);
    return result;
  }
  if (WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) result.signal = WTERMSIG(status);
  result.output = ReadFile(started.log);
  fs::remove(started.log);
  return result;
}

}  // namespace

RunResult RunU3mscan(const std::vector<std::string>& args, const fs::path& tmp_dir) {
  return Wait(Start({args, tmp_dir}));
}

std::vector<RunResult> RunU3mscanAll(const std::vector<RunSpec>& runs) {
  std::vector<Started> started;
  for (const RunSpec& run : runs) started.push_back(Start(run));
  std::vector<RunResult> results;
  for (const Started& s : started) results.push_back(Wait(s));
  return results;
}

::testing::AssertionResult CleanExit(const RunResult& run, int exit_code, const std::vector<std::string>& mentions) {
  if (run.signal != 0)
    return ::testing::AssertionFailure() << "killed by signal " << run.signal << " (" << strsignal(run.signal)
                                         << "); output:\n" << run.output;
  if (run.exit_code != exit_code)
    return ::testing::AssertionFailure() << "exit code " << run.exit_code << ", expected " << exit_code << "; output:\n"
                                         << run.output;
  for (const char* sign : {"AddressSanitizer", "LeakSanitizer", "runtime error:", "terminate called", "internal error",
                           "Segmentation fault", "std::bad_alloc", "core dumped"}) {
    if (run.output.find(sign) != std::string::npos)
      return ::testing::AssertionFailure() << "output shows \"" << sign << "\":\n" << run.output;
  }
  for (const std::string& mention : mentions) {
    if (run.output.find(mention) == std::string::npos)
      return ::testing::AssertionFailure() << "output does not mention \"" << mention << "\":\n" << run.output;
  }
  return ::testing::AssertionSuccess();
}

::testing::AssertionResult NothingIn(const fs::path& dir) {
  if (!fs::exists(dir)) return ::testing::AssertionSuccess();
  std::ostringstream found;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) found << "  " << entry.path().string() << "\n";
  if (found.str().empty()) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << dir.string() << " is not empty:\n" << found.str();
}

TempDir::TempDir() {
  static int counter = 0;
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string(info->test_suite_name()) + "_" + info->name();
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  path_ = fs::temp_directory_path() /
          ("u3mscan_hostile_" + name + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
  fs::remove_all(path_);
  fs::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ignored;
  fs::remove_all(path_, ignored);
}

fs::path CorpusDir() { return fs::path(U3MSCAN_SOURCE_DIR) / "tests" / "hostile"; }

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void WriteFile(const fs::path& path, const std::string& bytes) {
  if (path.has_parent_path()) fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

namespace {
void Put16(std::string& b, std::uint32_t v) {
  b.push_back(static_cast<char>(v & 0xFF));
  b.push_back(static_cast<char>((v >> 8) & 0xFF));
}
void Put32(std::string& b, std::uint32_t v) {
  Put16(b, v & 0xFFFF);
  Put16(b, v >> 16);
}
std::string RawDeflate(const std::string& data) {
  z_stream z{};
  deflateInit2(&z, 9, Z_DEFLATED, -15, 9, Z_DEFAULT_STRATEGY);
  std::string out(deflateBound(&z, data.size()), '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = static_cast<uInt>(data.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}
}  // namespace

std::string BuildZip(const std::vector<ZipEntrySpec>& entries) {
  std::string zip, central;
  constexpr std::uint32_t kDosTime = 0, kDosDate = (44u << 9) | (1u << 5) | 1u;  // 2024-01-01
  for (const ZipEntrySpec& e : entries) {
    const std::string stored = e.deflate ? RawDeflate(e.data) : e.data;
    const std::uint32_t crc =
        static_cast<std::uint32_t>(crc32(0, reinterpret_cast<const Bytef*>(e.data.data()), static_cast<uInt>(e.data.size())));
    const std::uint32_t offset = static_cast<std::uint32_t>(zip.size());
    const std::uint16_t method = e.deflate ? 8 : 0;
    Put32(zip, 0x04034b50);
    Put16(zip, 20);
    Put16(zip, 0x0800);
    Put16(zip, method);
    Put16(zip, kDosTime);
    Put16(zip, kDosDate);
    Put32(zip, crc);
    Put32(zip, static_cast<std::uint32_t>(stored.size()));
    Put32(zip, static_cast<std::uint32_t>(e.data.size()));
    Put16(zip, static_cast<std::uint32_t>(e.name.size()));
    Put16(zip, 0);
    zip += e.name;
    zip += stored;
    Put32(central, 0x02014b50);
    Put16(central, 0x003F);
    Put16(central, 20);
    Put16(central, 0x0800);
    Put16(central, method);
    Put16(central, kDosTime);
    Put16(central, kDosDate);
    Put32(central, crc);
    Put32(central, static_cast<std::uint32_t>(stored.size()));
    Put32(central, static_cast<std::uint32_t>(e.data.size()));
    Put16(central, static_cast<std::uint32_t>(e.name.size()));
    Put16(central, 0);
    Put16(central, 0);
    Put16(central, 0);
    Put16(central, 0);
    Put32(central, 0);
    Put32(central, offset);
    central += e.name;
  }
  const std::uint32_t central_offset = static_cast<std::uint32_t>(zip.size());
  zip += central;
  Put32(zip, 0x06054b50);
  Put16(zip, 0);
  Put16(zip, 0);
  Put16(zip, static_cast<std::uint32_t>(entries.size()));
  Put16(zip, static_cast<std::uint32_t>(entries.size()));
  Put32(zip, static_cast<std::uint32_t>(central.size()));
  Put32(zip, central_offset);
  Put16(zip, 0);
  return zip;
}

}  // namespace u3mscan::hostile
