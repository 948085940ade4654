#pragma once
// SHA-256 (FIPS 180-4), self-contained so that model files and checkpoints can
// be fingerprinted (e.g. checked against a MANIFEST) without pulling in OpenSSL.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace pnet {

/// Incremental SHA-256 (FIPS 180-4): feed data in any chunking, the digest is the same.
class Sha256 {
public:
    Sha256();

    void update(const void* data, std::size_t size);

    /// Finishes and returns the 64-character lowercase hex digest; the object is then reset,
    /// so one instance can hash several messages in turn.
    std::string hex_digest();

private:
    void reset();
    void process_block(const std::uint8_t* block);

    std::array<std::uint32_t, 8> state_;
    std::array<std::uint8_t, 64> buffer_;  // pending bytes of an incomplete block
    std::size_t buffered_ = 0;             // bytes used in buffer_ (always < 64)
    std::uint64_t length_ = 0;             // total message length in bytes
};

/// sha256 of a byte string, lowercase hex.
std::string sha256_hex(const std::string& bytes);

/// sha256 of a file's bytes, lowercase hex. Throws std::runtime_error naming the path if the
/// file cannot be opened or read, so a missing model file is reported rather than hashed as "".
std::string sha256_file_hex(const std::string& path);

}  // namespace pnet
