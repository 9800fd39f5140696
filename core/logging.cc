#include "core/logging.h"

#include <atomic>
#include <iostream>
#include <mutex>

namespace u3mscan {
namespace {
std::atomic<LogLevel> g_level{LogLevel::kInfo};
std::mutex g_mutex;

const char* LevelName(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug: return "debug";
    case LogLevel::kInfo: return "info";
    case LogLevel::kWarning: return "warning";
    case LogLevel::kError: return "error";
    case LogLevel::kOff: break;
  }
  return "";
}

LogSink& Sink() {
  static LogSink sink = [](LogLevel level, const std::string& message) {
    std::cerr << "[" << LevelName(level) << "] " << message << "\n";
  };
  return sink;
}
}  // namespace

void SetLogLevel(LogLevel level) { g_level = level; }
LogLevel GetLogLevel() { return g_level; }

void SetLogSink(LogSink sink) {
  std::lock_guard lock(g_mutex);
  Sink() = std::move(sink);
}

void Log(LogLevel level, const std::string& message) {
  if (level < g_level.load() || level == LogLevel::kOff) return;
  std::lock_guard lock(g_mutex);
  if (Sink()) Sink()(level, message);
}

}  // namespace u3mscan
