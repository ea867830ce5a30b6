// Releasing the GIL, waiting, and text from the server, for the bindings.
//
// The GIL is taken back explicitly, never in a destructor: once Python
// finalizes, taking the GIL ends the thread by unwinding its stack, which
// must not pass through a destructor (std::terminate).
#pragma once

#include <pybind11/pybind11.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <exception>
#include <string>
#include <string_view>
#include <type_traits>

namespace terrane::python {

namespace py = pybind11;

// Set by the module's atexit hook: waits raise at once from then on.
inline std::atomic<bool> g_exiting{false};

// True if this thread holds the GIL (false before Python starts or after
// it finalized).
inline bool holds_gil() { return Py_IsInitialized() && PyGILState_Check(); }

// Runs f with the GIL released (if this thread holds it).
template <class F>
auto without_gil(F&& f) -> decltype(f()) {
  if (!holds_gil()) return f();
  PyThreadState* saved = PyEval_SaveThread();
  std::exception_ptr error;
  if constexpr (std::is_void_v<decltype(f())>) {
    try {
      f();
    } catch (...) {
      error = std::current_exception();
    }
    PyEval_RestoreThread(saved);
    if (error) std::rethrow_exception(error);
  } else {
    decltype(f()) result{};
    try {
      result = f();
    } catch (...) {
      error = std::current_exception();
    }
    PyEval_RestoreThread(saved);
    if (error) std::rethrow_exception(error);
    return result;
  }
}

// Waits for wait(slice) to return true, in slices of at most 200 ms with the
// GIL released, checking for Ctrl-C (and Python exiting) between them.
// Returns false at the deadline; raises KeyboardInterrupt (or whatever the
// signal handler raised) or ConnectionError when Python exits.
template <class SliceWait>
bool wait_interruptibly(std::chrono::milliseconds timeout, SliceWait&& wait) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + timeout;
  for (;;) {
    if (g_exiting.load()) {
      PyErr_SetString(PyExc_ConnectionError, "Python is exiting: the terrane clients are closed");
      throw py::error_already_set();
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    const auto slice = std::max(std::chrono::milliseconds(0), std::min(left, std::chrono::milliseconds(200)));
    if (without_gil([&] { return wait(slice); })) return true;
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    if (Clock::now() >= deadline) return false;
  }
}

// Text from the server (reasons, notices, material names) as valid UTF-8:
// each byte that does not start a well-formed sequence becomes U+FFFD, so
// Python never fails to decode what a server sent.
inline std::string utf8(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  const auto* p = reinterpret_cast<const unsigned char*>(s.data());
  const std::size_t n = s.size();
  for (std::size_t i = 0; i < n;) {
    const unsigned char c = p[i];
    std::size_t len = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xE ? 3 : (c >> 3) == 0x1E ? 4 : 0;
    bool ok = len != 0 && i + len <= n;
    for (std::size_t k = 1; ok && k < len; ++k) ok = (p[i + k] & 0xC0) == 0x80;
    if (ok && len > 1) {
      // No overlong forms, surrogates or code points beyond U+10FFFF.
      std::uint32_t cp = c & (0x7F >> len);
      for (std::size_t k = 1; k < len; ++k) cp = (cp << 6) | (p[i + k] & 0x3F);
      static constexpr std::uint32_t kMin[] = {0, 0, 0x80, 0x800, 0x10000};
      ok = cp >= kMin[len] && cp <= 0x10FFFF && (cp < 0xD800 || cp > 0xDFFF);
    }
    if (ok) {
      out.append(s.substr(i, len));
      i += len;
    } else {
      out += "\xEF\xBF\xBD";
      ++i;
    }
  }
  return out;
}

}  // namespace terrane::python
