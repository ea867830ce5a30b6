// Test support: for conditions nothing signals (another process's HTTP
// answers, a counter moved by the server's own threads), poll until the
// condition holds or a generous deadline passes. One place for the polling,
// with a backoff from 1 ms to 50 ms, so no test sleeps for a duration.
#pragma once

#include <algorithm>
#include <chrono>
#include <thread>

namespace terrane::testing_support {

template <class Pred>
bool eventually(Pred pred, std::chrono::milliseconds deadline = std::chrono::seconds(60)) {
  const auto end = std::chrono::steady_clock::now() + deadline;
  auto pause = std::chrono::milliseconds(1);
  while (!pred()) {
    if (std::chrono::steady_clock::now() >= end) return pred();
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::milliseconds(50));
  }
  return true;
}

}  // namespace terrane::testing_support
