// Error policy (see README "Errors"): readers and parsers return Status / Result<T> whose
// message names the file, the position and what was expected. Programming mistakes trip
// SA_CHECK. Only cli/ prints and chooses the exit code.
#pragma once
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <utility>

namespace sa {

enum class ErrorKind { kNone = 0, kBadInput = 2, kInternal = 1 };

class Status {
 public:
  Status() = default;
  static Status ok() { return {}; }
  static Status badInput(std::string msg) { return Status(ErrorKind::kBadInput, std::move(msg)); }
  static Status internal(std::string msg) { return Status(ErrorKind::kInternal, std::move(msg)); }
  bool isOk() const { return kind_ == ErrorKind::kNone; }
  explicit operator bool() const { return isOk(); }
  ErrorKind kind() const { return kind_; }
  const std::string& message() const { return message_; }

 private:
  Status(ErrorKind k, std::string m) : kind_(k), message_(std::move(m)) {}
  ErrorKind kind_ = ErrorKind::kNone;
  std::string message_;
};

// A value or the Status that explains why there is none.
template <class T>
class Result {
 public:
  Result(T v) : value_(std::move(v)) {}
  Result(Status s) : status_(std::move(s)) {}
  bool isOk() const { return value_.has_value(); }
  explicit operator bool() const { return isOk(); }
  const Status& status() const { return status_; }
  T& value() { return *value_; }
  const T& value() const { return *value_; }
  T* operator->() { return &*value_; }
  T& operator*() { return *value_; }

 private:
  std::optional<T> value_;
  Status status_;
};

[[noreturn]] void checkFailed(const char* expr, const char* file, int line);

}  // namespace sa

#define SA_CHECK(cond) \
  do { if (!(cond)) ::sa::checkFailed(#cond, __FILE__, __LINE__); } while (0)
#ifdef NDEBUG
#define SA_DCHECK(cond) do { (void)sizeof(cond); } while (0)
#else
#define SA_DCHECK(cond) SA_CHECK(cond)
#endif
#define SA_RETURN_IF_ERROR(expr) \
  do { ::sa::Status sa_st_ = (expr); if (!sa_st_.isOk()) return sa_st_; } while (0)
