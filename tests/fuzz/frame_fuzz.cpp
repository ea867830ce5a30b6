// Fuzz target: the TCP frame reader and message verifier on arbitrary bytes.
#include <cstddef>
#include <cstdint>
#include <span>

#include "protocol/framing.h"
#include "protocol/terrane_generated.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  terrane::FrameReader reader(4096);
  (void)reader.feed(std::span(data, size), [](std::span<const std::uint8_t> body) {
    auto msg = terrane::verify_message(body);
    if (msg.ok()) {
      // Touch the verified body the way a handler would.
      volatile auto type = (*msg)->body_type();
      (void)type;
    }
  });
  // The body alone, as a message.
  (void)terrane::verify_message(std::span(data, size));
  return 0;
}
