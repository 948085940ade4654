#pragma once
// SHA-256 (FIPS 180-4) through OpenSSL's libcrypto (EVP), so that model files
// and checkpoints are fingerprinted (e.g. checked against a MANIFEST) by the
// system's audited implementation.
#include <cstddef>
#include <memory>
#include <string>

namespace pnet {

/// Incremental SHA-256: feed data in any chunking, the digest is the same.
class Sha256 {
public:
    Sha256();
    ~Sha256();
    Sha256(Sha256&&) noexcept;
    Sha256& operator=(Sha256&&) noexcept;
    Sha256(const Sha256&) = delete;
    Sha256& operator=(const Sha256&) = delete;

    void update(const void* data, std::size_t size);

    /// Finishes and returns the 64-character lowercase hex digest; the object is then reset,
    /// so one instance can hash several messages in turn.
    std::string hex_digest();

private:
    struct Context;
    std::unique_ptr<Context> context_;
};

/// sha256 of a byte string, lowercase hex.
std::string sha256_hex(const std::string& bytes);

/// sha256 of a file's bytes, lowercase hex. Throws std::runtime_error naming the path if the
/// file cannot be opened or read, so a missing model file is reported rather than hashed as "".
std::string sha256_file_hex(const std::string& path);

}  // namespace pnet
