#pragma once
// Logging: one process-wide sink with levels. Libraries log what they did and skipped; the CLI
// decides where it goes (stderr by default, silenced by --quiet).

#include <functional>
#include <sstream>
#include <string>

namespace u3mscan {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3, kOff = 4 };

using LogSink = std::function<void(LogLevel, const std::string&)>;

// Messages below `level` are dropped. Default: kInfo.
void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
// Replaces the sink (default: "[level] message" lines on stderr). Thread-safe to call Log() from
// worker threads; the sink is called under a mutex.
void SetLogSink(LogSink sink);
void Log(LogLevel level, const std::string& message);

// Stream-style helper: LogStream(LogLevel::kInfo) << "read " << n << " frames";
class LogStream {
 public:
  explicit LogStream(LogLevel level) : level_(level) {}
  ~LogStream() { Log(level_, stream_.str()); }
  template <typename T>
  LogStream& operator<<(const T& value) {
    stream_ << value;
    return *this;
  }

 private:
  LogLevel level_;
  std::ostringstream stream_;
};

inline LogStream LogInfo() { return LogStream(LogLevel::kInfo); }
inline LogStream LogWarning() { return LogStream(LogLevel::kWarning); }
inline LogStream LogDebug() { return LogStream(LogLevel::kDebug); }
inline LogStream LogError() { return LogStream(LogLevel::kError); }

}  // namespace u3mscan
