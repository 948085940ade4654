#include "pnet/io/atomic_file.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <system_error>

namespace pnet {

namespace fs = std::filesystem;

namespace {

// Removes the temporary file, ignoring errors: it is called on the way out of a failure that
// is already being reported, and a failed clean-up must not mask that failure.
void remove_quietly(const std::string& tmp) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
}

}  // namespace

void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write) {
    // Same folder as path, so that the rename stays within one file system and is atomic; the
    // pid keeps concurrent processes writing the same path from sharing a temporary file.
    const std::string tmp = path + ".tmp." + std::to_string(::getpid());

    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) {
        throw std::runtime_error(path + ": cannot create temporary file " + tmp + ": " + std::strerror(errno));
    }
    errno = 0;  // the streams do not say why a write failed; the failed write(2) leaves errno
    try {
        write(out);
    } catch (const std::exception& e) {
        out.close();
        remove_quietly(tmp);
        throw std::runtime_error(path + ": writing failed: " + e.what());
    } catch (...) {
        out.close();
        remove_quietly(tmp);
        throw std::runtime_error(path + ": writing failed: unknown exception");
    }
    auto reason = [] { return errno != 0 ? std::string(std::strerror(errno)) : std::string("an I/O error"); };
    out.flush();
    if (!out) {
        const std::string why = reason();
        out.close();
        remove_quietly(tmp);
        throw std::runtime_error(path + ": writing " + tmp + " failed: " + why);
    }
    out.close();  // close() can fail too, e.g. when the last buffered block cannot be written
    if (out.fail()) {
        const std::string why = reason();
        remove_quietly(tmp);
        throw std::runtime_error(path + ": closing " + tmp + " failed: " + why);
    }

    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
        remove_quietly(tmp);
        throw std::runtime_error(path + ": cannot rename " + tmp + " over it: " + ec.message());
    }
}

void write_text_atomically(const std::string& path, const std::string& text) {
    write_file_atomically(path, [&](std::ostream& out) { out.write(text.data(), std::streamsize(text.size())); });
}

}  // namespace pnet
