#include "pnet/io/sha256.hpp"

#include <openssl/evp.h>

#include <fstream>
#include <stdexcept>
#include <vector>

namespace pnet {

namespace {

[[noreturn]] void openssl_failure(const char* what) {
    throw std::runtime_error(std::string("sha256: OpenSSL ") + what + " failed");
}

}  // namespace

struct Sha256::Context {
    EVP_MD_CTX* ctx = EVP_MD_CTX_new();
    Context() {
        if (!ctx) openssl_failure("EVP_MD_CTX_new");
        start();
    }
    ~Context() { EVP_MD_CTX_free(ctx); }
    void start() {
        if (EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) != 1) openssl_failure("EVP_DigestInit_ex");
    }
};

Sha256::Sha256() : context_(std::make_unique<Context>()) {}
Sha256::~Sha256() = default;
Sha256::Sha256(Sha256&&) noexcept = default;
Sha256& Sha256::operator=(Sha256&&) noexcept = default;

void Sha256::update(const void* data, std::size_t size) {
    if (size > 0 && EVP_DigestUpdate(context_->ctx, data, size) != 1) openssl_failure("EVP_DigestUpdate");
}

std::string Sha256::hex_digest() {
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int length = 0;
    if (EVP_DigestFinal_ex(context_->ctx, digest, &length) != 1) openssl_failure("EVP_DigestFinal_ex");
    context_->start();
    static const char kHex[] = "0123456789abcdef";
    std::string out;
    out.reserve(2 * length);
    for (unsigned int i = 0; i < length; ++i) {
        out.push_back(kHex[digest[i] >> 4]);
        out.push_back(kHex[digest[i] & 0xf]);
    }
    return out;
}

std::string sha256_hex(const std::string& bytes) {
    Sha256 hasher;
    hasher.update(bytes.data(), bytes.size());
    return hasher.hex_digest();
}

std::string sha256_file_hex(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot read (failed to open file)");
    Sha256 hasher;
    std::vector<char> chunk(1 << 16);
    while (in) {
        in.read(chunk.data(), static_cast<std::streamsize>(chunk.size()));
        const std::streamsize got = in.gcount();
        if (got > 0) hasher.update(chunk.data(), static_cast<std::size_t>(got));
    }
    // eof alone is the normal end; badbit means the read itself failed part-way.
    if (in.bad()) throw std::runtime_error(path + ": cannot read (I/O error)");
    return hasher.hex_digest();
}

}  // namespace pnet
