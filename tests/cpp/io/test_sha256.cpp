#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>

#include "pnet/io/sha256.hpp"

namespace pnet {
namespace {

// Bytes 'a', 'b', ..., 'z', 'a', ... of the given length; the expected digests below for
// these messages come from coreutils `sha256sum`.
std::string alphabet_message(std::size_t length) {
    std::string s(length, '\0');
    for (std::size_t i = 0; i < length; ++i) s[i] = static_cast<char>('a' + i % 26);
    return s;
}

// Non-text bytes, so that high-bit and zero bytes go through the block parser too.
std::string binary_message(std::size_t length) {
    std::string s(length, '\0');
    for (std::size_t i = 0; i < length; ++i) s[i] = static_cast<char>((i * 151 + 7) & 0xff);
    return s;
}

TEST(Sha256, NistEmptyString) {
    EXPECT_EQ(sha256_hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

TEST(Sha256, NistAbc) {
    EXPECT_EQ(sha256_hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}

TEST(Sha256, Nist448Bits) {
    EXPECT_EQ(sha256_hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
              "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
}

TEST(Sha256, NistMillionAIncremental) {
    const std::string chunk(1000, 'a');
    const std::size_t sizes[] = {1, 7, 64, 1000, 63, 129, 3};
    Sha256 hasher;
    std::size_t fed = 0;
    for (std::size_t k = 0; fed < 1000000; ++k) {
        const std::size_t n = std::min(sizes[k % 7], std::size_t(1000000) - fed);
        hasher.update(chunk.data(), n);
        fed += n;
    }
    EXPECT_EQ(hasher.hex_digest(), "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST(Sha256, PaddingBoundaryLengths) {
    const struct {
        std::size_t length;
        const char* digest;
    } cases[] = {
        {55, "595615dbe4f0f407ae397d08b4c2cb870cb9b0e11937416f950c5160acf9c005"},
        {56, "784f623b787495078e93ff28a25b581df0584055a7e71d8cd90c454716b92f51"},
        {57, "808f0738aa4401bdee842e5a15a7baad5809f976d8eb6f9bd2683cebd2e8d671"},
        {63, "5ca3e1ef5207490eac01a795e5cc94d59582a5118bf9534665c8668d87aa647c"},
        {64, "2fcd5a0d60e4c941381fcc4e00a4bf8be422c3ddfafb93c809e8d1e2bfffae8e"},
        {65, "1b3cd1877ab2f2f19f7be001722554f336cb799df0329de0bb4c118dc6abc06d"},
    };
    for (const auto& c : cases) {
        EXPECT_EQ(sha256_hex(alphabet_message(c.length)), c.digest) << "length " << c.length;
    }
}

TEST(Sha256, SplitAtEveryBoundaryMatchesOneUpdate) {
    const std::string message = binary_message(130);
    const std::string expected = sha256_hex(message);
    for (std::size_t split = 0; split <= message.size(); ++split) {
        Sha256 hasher;
        hasher.update(message.data(), split);
        hasher.update(message.data() + split, message.size() - split);
        EXPECT_EQ(hasher.hex_digest(), expected) << "split at " << split;
    }
}

TEST(Sha256, DigestResetsTheObject) {
    Sha256 hasher;
    hasher.update("abc", 3);
    EXPECT_EQ(hasher.hex_digest(), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    EXPECT_EQ(hasher.hex_digest(), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
    hasher.update("abc", 3);
    EXPECT_EQ(hasher.hex_digest(), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}

TEST(Sha256, FileMatchesInMemory) {
    // Larger than one 64 KiB read chunk and not a multiple of 64.
    const std::string content = binary_message(200003);
    const std::string path = ::testing::TempDir() + "pnet_test_sha256_file.bin";
    {
        std::ofstream out(path, std::ios::binary);
        ASSERT_TRUE(out);
        out.write(content.data(), static_cast<std::streamsize>(content.size()));
    }
    EXPECT_EQ(sha256_file_hex(path), sha256_hex(content));
    std::remove(path.c_str());
}

TEST(Sha256, MissingFileThrowsWithPath) {
    const std::string path = ::testing::TempDir() + "pnet_test_sha256_no_such_file.bin";
    std::remove(path.c_str());
    try {
        sha256_file_hex(path);
        FAIL() << "expected std::runtime_error";
    } catch (const std::runtime_error& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace pnet
