#pragma once
// Scratch files for the C++ tests: a temporary directory removed at the end,
// whole-file read/write, and the check that an error names its file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

namespace pnet::test {

/// A fresh directory under the system temp folder, removed at the end.
class TempDir {
public:
    TempDir() {
        path_ = std::filesystem::temp_directory_path() /
                ("pnet_test_" + std::to_string(std::random_device{}()) + "_" + std::to_string(::getpid()));
        std::filesystem::create_directories(path_);
    }
    ~TempDir() { std::filesystem::remove_all(path_); }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;

    std::string file(const std::string& name) const { return (path_ / name).string(); }
    /// Names of the entries, e.g. to see that no temporary file was left behind.
    std::vector<std::string> entries() const {
        std::vector<std::string> names;
        for (const auto& e : std::filesystem::directory_iterator(path_)) names.push_back(e.path().filename().string());
        return names;
    }

private:
    std::filesystem::path path_;
};

inline std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline void write_file(const std::string& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary) << bytes;
}

/// Runs fn, expecting an exception of type E whose message starts with `path`
/// and contains `needle`.
template <typename E, typename Fn>
void expect_error(Fn&& fn, const std::string& path, const std::string& needle) {
    try {
        fn();
        ADD_FAILURE() << "no exception for " << path;
    } catch (const E& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind(path, 0), 0u) << "message does not start with the path: " << what;
        EXPECT_NE(what.find(needle), std::string::npos) << "expected \"" << needle << "\" in: " << what;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "wrong exception type for " << path << ": " << e.what();
    }
}

}  // namespace pnet::test
