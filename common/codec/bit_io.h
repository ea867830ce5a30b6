// Little bit-stream reader and writer for the network voxel codec, and the
// one LEB128 varint of every Terrane format that has one.
//
// Bits are packed LSB-first: the first bit written is bit 0 of byte 0, a
// k-bit value is written low bit first. The writer appends to a caller-sized
// byte buffer; the reader never touches memory outside its span (past the end
// it feeds zero bits and remembers that it did, so the caller can report
// truncation).
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

namespace terrane {

namespace bit_io_detail {
inline std::uint64_t load_le64(const std::uint8_t* p) {
  std::uint64_t w;
  std::memcpy(&w, p, 8);
  if constexpr (std::endian::native == std::endian::big) w = __builtin_bswap64(w);
  return w;
}
inline void store_le64(std::uint8_t* p, std::uint64_t w) {
  if constexpr (std::endian::native == std::endian::big) w = __builtin_bswap64(w);
  std::memcpy(p, &w, 8);
}
}  // namespace bit_io_detail

// Writes bits into [begin, begin + capacity). The caller guarantees capacity
// covers everything written plus 8 bytes of slack (whole 64-bit stores).
class BitWriter {
 public:
  explicit BitWriter(std::uint8_t* begin) : begin_(begin), cur_(begin) {}

  // Precondition: bits <= 32 and value < 2^bits.
  void put(std::uint32_t value, unsigned bits) {
    acc_ |= std::uint64_t{value} << count_;
    count_ += bits;
    if (count_ >= 32) {
      bit_io_detail::store_le64(cur_, acc_);
      cur_ += 4;
      acc_ >>= 32;
      count_ -= 32;
    }
  }
  // Flushes the partial last byte, zero padded. Returns the bytes written.
  std::size_t finish() {
    bit_io_detail::store_le64(cur_, acc_);
    cur_ += (count_ + 7) / 8;
    acc_ = 0;
    count_ = 0;
    return static_cast<std::size_t>(cur_ - begin_);
  }
  std::size_t bit_count() const { return static_cast<std::size_t>(cur_ - begin_) * 8 + count_; }

 private:
  std::uint8_t* begin_;
  std::uint8_t* cur_;
  std::uint64_t acc_ = 0;
  unsigned count_ = 0;
};

// Reads bits from a span. refill() makes at least 56 bits available; the
// codec's decoder refills once every few tokens (a token needs at most 18
// bits at its start, and long length codes refill on their own).
//
// Every member is inlined so that a reader living in a local variable stays
// in registers (a call that took its address would pin it to memory).
class BitReader {
 public:
  BitReader(const std::uint8_t* begin, const std::uint8_t* end)
      : begin_(begin), cur_(begin), end_(end), fast_end_(end - begin >= 8 ? end - 7 : begin) {}

  // While 8 bytes remain: one unaligned 64-bit load, no branch on the bit
  // count. The bits above count_ in buf_ are zero or the stream's next bits,
  // so or-ing the same bytes in again changes nothing. Near the end: whole
  // bytes while they fit, zero bytes past the end (counted, so the caller can
  // report truncation); nothing outside [begin, end) is read.
  [[gnu::always_inline]] void refill() {
    if (cur_ < fast_end_) [[likely]] {  // at least 8 bytes left
      buf_ |= bit_io_detail::load_le64(cur_) << count_;
      cur_ += (63 - count_) >> 3;
      count_ |= 56;
    } else {
      while (count_ <= 56) {
        std::uint64_t byte = 0;
        if (cur_ < end_) {
          byte = *cur_++;
        } else {
          ++zero_bytes_;  // past the end: feed zeros, remember the overrun
        }
        buf_ |= byte << count_;
        count_ += 8;
      }
    }
  }
  // The next 64 bits; only the low available() are meaningful.
  [[gnu::always_inline]] std::uint64_t bits() const { return buf_; }
  // Precondition: bits <= available().
  [[gnu::always_inline]] std::uint32_t peek(unsigned bits) const {
    return static_cast<std::uint32_t>(buf_ & ((std::uint64_t{1} << bits) - 1));
  }
  [[gnu::always_inline]] void skip(unsigned bits) {
    buf_ >>= bits;
    count_ -= bits;
  }
  [[gnu::always_inline]] std::uint32_t get(unsigned bits) {
    const std::uint32_t v = peek(bits);
    skip(bits);
    return v;
  }
  // Zero bits before the next one bit in the buffer (64 if the buffer is 0).
  unsigned trailing_zeros() const { return static_cast<unsigned>(std::countr_zero(buf_)); }
  unsigned available() const { return count_; }

  // Bits consumed so far, counting any zero bits fed past the end.
  std::size_t bit_position() const {
    return (static_cast<std::size_t>(cur_ - begin_) + zero_bytes_) * 8 - count_;
  }
  std::size_t bit_size() const { return static_cast<std::size_t>(end_ - begin_) * 8; }
  bool overran() const { return bit_position() > bit_size(); }
  // True when a one bit follows bit_position() before the end of the span
  // (a slow scan for error reporting).
  bool one_bit_ahead() const {
    std::size_t pos = bit_position();
    const std::size_t size = bit_size();
    for (; pos < size && pos % 8 != 0; ++pos) {
      if ((begin_[pos / 8] >> (pos % 8)) & 1) return true;
    }
    for (std::size_t at = pos / 8; at < static_cast<std::size_t>(end_ - begin_); ++at) {
      if (begin_[at] != 0) return true;
    }
    return false;
  }

 private:
  const std::uint8_t* begin_;
  const std::uint8_t* cur_;
  const std::uint8_t* end_;
  const std::uint8_t* fast_end_;  // cur_ < fast_end_: 8 bytes can be loaded at cur_
  std::uint64_t buf_ = 0;
  unsigned count_ = 0;
  std::size_t zero_bytes_ = 0;
};

// LEB128 varints: 7 bits per byte, low bits first, the top bit set on every
// byte but the last. The update batch (NET_CODEC.md), the LZ4 block's size
// (BYTE_RLE.md) and the stream batch (PROTOCOL.md) write and read them here;
// each format sets its own length limit and names its own errors.

// Zigzag: a signed integer as an unsigned one whose size follows its
// magnitude (0, -1, 1, -2, 2 ... -> 0, 1, 2, 3, 4 ...), so small deltas of
// either sign make short varints. The same value for a 32-bit input as the
// 32-bit formula.
inline std::uint64_t zigzag(std::int64_t v) {
  return (static_cast<std::uint64_t>(v) << 1) ^ static_cast<std::uint64_t>(v >> 63);
}
inline std::int64_t unzigzag(std::uint64_t z) {
  return static_cast<std::int64_t>(z >> 1) ^ -static_cast<std::int64_t>(z & 1);
}

// Appends v in the fewest bytes (1 to 10).
inline void put_varint(std::uint64_t v, std::vector<std::uint8_t>& out) {
  while (v >= 0x80) {
    out.push_back(static_cast<std::uint8_t>(v | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<std::uint8_t>(v));
}

enum class VarintRead : std::uint8_t {
  kOk,         // v holds the value, pos is just past its last byte
  kTruncated,  // the span ended first: pos is at its end
  kTooLong,    // max_bytes bytes all had the top bit set: pos is past them
};

// Reads one varint of at most max_bytes (<= 10) bytes starting at pos,
// advancing pos over the bytes read. Bits above the 64th are dropped, and
// nothing is checked beyond the length: callers judge the value (range,
// minimal length) themselves. Nothing outside bytes is read.
inline VarintRead get_varint(std::span<const std::uint8_t> bytes, std::size_t& pos, std::size_t max_bytes,
                             std::uint64_t& v) {
  v = 0;
  for (std::size_t i = 0; i < max_bytes; ++i) {
    if (pos >= bytes.size()) return VarintRead::kTruncated;
    const std::uint8_t b = bytes[pos++];
    v |= std::uint64_t{b & 0x7Fu} << (7 * i);
    if ((b & 0x80) == 0) return VarintRead::kOk;
  }
  return VarintRead::kTooLong;
}

}  // namespace terrane
