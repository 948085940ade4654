#include "pnet/io/checkpoint_arrays.hpp"

#include <filesystem>
#include <fstream>
#include <iterator>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/sha256.hpp"
#include "pnet/io/file_errors.hpp"

namespace pnet {

namespace {

constexpr char kSealMark[] = "PNETSHA2";
constexpr std::size_t kSealBytes = 8 + 64;  // the mark, then 64 hex digits

}  // namespace

void write_sealed_checkpoint(const std::string& path, const std::function<void(std::ostream&)>& write) {
    std::ostringstream payload(std::ios::binary);
    write(payload);
    std::string bytes = std::move(payload).str();
    const std::string digest = sha256_hex(bytes);
    bytes.append(kSealMark, 8);
    bytes += digest;
    write_text_atomically(path, bytes);
}

std::istringstream read_sealed_checkpoint(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        std::error_code ec;
        if (!std::filesystem::exists(path, ec)) throw FileNotFoundError(path + ": no such checkpoint file");
        throw std::invalid_argument(path + ": cannot open the checkpoint");
    }
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) throw std::invalid_argument(path + ": cannot read the checkpoint");
    if (bytes.size() < kSealBytes || bytes.compare(bytes.size() - kSealBytes, 8, kSealMark) != 0)
        throw std::invalid_argument(path + ": not a PlasticityNet checkpoint, or a truncated one (no checksum at its end)");
    const std::string expected = bytes.substr(bytes.size() - 64);
    bytes.resize(bytes.size() - kSealBytes);
    if (sha256_hex(bytes) != expected)
        throw std::invalid_argument(path + ": corrupt checkpoint (its bytes do not match its SHA-256 checksum)");
    return std::istringstream(std::move(bytes), std::ios::binary);
}

}  // namespace pnet
