#include <gtest/gtest.h>
#include <unistd.h>
#include <png.h>
#include <zlib.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/io/png.hpp"

#include "support/temp_dir.hpp"

namespace pnet {
namespace {

using namespace test;  // TempDir, read_file, write_file, expect_error
namespace fs = std::filesystem;

std::uint32_t be32(const std::string& s, std::size_t at) {
    return (std::uint32_t(std::uint8_t(s[at])) << 24) | (std::uint32_t(std::uint8_t(s[at + 1])) << 16) |
           (std::uint32_t(std::uint8_t(s[at + 2])) << 8) | std::uint32_t(std::uint8_t(s[at + 3]));
}

Image random_image(int width, int height, unsigned seed) {
    std::mt19937 rng(seed);
    Image img(width, height);
    for (auto& byte : img.rgb) byte = std::uint8_t(rng() & 0xff);
    return img;
}

TEST(Image, SetGetBlendFill) {
    Image img(4, 3, {10, 20, 30});
    EXPECT_EQ(img.rgb.size(), 36u);
    EXPECT_EQ(img.get(3, 2), (Rgb{10, 20, 30}));
    img.set(1, 2, {200, 100, 0});
    EXPECT_EQ(img.get(1, 2), (Rgb{200, 100, 0}));
    EXPECT_EQ(img.rgb[3 * (2 * 4 + 1)], 200);  // row-major, 3 bytes per pixel
    img.set(-1, 0, {1, 1, 1});                 // outside: ignored
    img.set(4, 0, {1, 1, 1});
    img.blend(0, 0, {110, 220, 30}, 0.5);
    EXPECT_EQ(img.get(0, 0), (Rgb{60, 120, 30}));
    img.blend(0, 1, {0, 0, 0}, 0.0);
    EXPECT_EQ(img.get(0, 1), (Rgb{10, 20, 30}));
    img.fill({255, 255, 255});
    for (auto byte : img.rgb) EXPECT_EQ(byte, 255);
}

TEST(Png, RoundTripAndHeader) {
    TempDir dir;
    const std::string path = dir.file("image.png");
    const Image img = random_image(37, 23, 11);
    write_png(path, img);

    const std::string bytes = read_file(path);
    ASSERT_GT(bytes.size(), 33u);
    EXPECT_EQ(bytes.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    EXPECT_EQ(be32(bytes, 8), 13u);  // IHDR length
    EXPECT_EQ(bytes.substr(12, 4), "IHDR");
    EXPECT_EQ(be32(bytes, 16), 37u);
    EXPECT_EQ(be32(bytes, 20), 23u);
    EXPECT_EQ(bytes[24], 8);  // bit depth
    EXPECT_EQ(bytes[25], 2);  // colour type RGB
    EXPECT_EQ(bytes[28], 0);  // not interlaced
    EXPECT_EQ(bytes.substr(bytes.size() - 12), std::string("\0\0\0\0IEND\xae\x42\x60\x82", 12));

    const Image back = read_png_rgb(path);
    EXPECT_EQ(back.width, 37);
    EXPECT_EQ(back.height, 23);
    EXPECT_EQ(back.rgb, img.rgb);
}

// A PNG written as other encoders do, with a different row filter on each row (None, Sub, Up,
// Average, Paeth, ...) and the data split over two IDAT chunks: read_png_rgb must undo them all.
TEST(Png, ReadsAllRowFilters) {
    const int w = 9, h = 10;
    const Image img = random_image(w, h, 5);
    const int row = 3 * w;
    std::vector<std::uint8_t> raw;
    for (int y = 0; y < h; ++y) {
        const int filter = y % 5;
        raw.push_back(std::uint8_t(filter));
        for (int i = 0; i < row; ++i) {
            auto at = [&](int yy, int ii) { return yy < 0 || ii < 0 ? 0 : int(img.rgb[std::size_t(yy * row + ii)]); };
            const int x = at(y, i), a = at(y, i - 3), b = at(y - 1, i), c = at(y - 1, i - 3);
            const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
            const int paeth = pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
            const int predictor[5] = {0, a, b, (a + b) / 2, paeth};
            raw.push_back(std::uint8_t(x - predictor[filter]));
        }
    }
    uLongf size = compressBound(uLong(raw.size()));
    std::vector<std::uint8_t> z(size);
    ASSERT_EQ(compress2(z.data(), &size, raw.data(), uLong(raw.size()), 9), Z_OK);

    std::string png("\x89PNG\r\n\x1a\n", 8);
    auto chunk = [&](const std::string& type, const std::string& data) {
        for (int k = 3; k >= 0; --k) png.push_back(char((data.size() >> (8 * k)) & 0xff));
        const std::string body = type + data;
        png += body;
        const uLong crc = crc32(0L, reinterpret_cast<const Bytef*>(body.data()), uInt(body.size()));
        for (int k = 3; k >= 0; --k) png.push_back(char((crc >> (8 * k)) & 0xff));
    };
    chunk("IHDR", std::string("\0\0\0\x09\0\0\0\x0a\x08\x02\0\0\0", 13));
    chunk("tEXt", std::string("Comment\0ancillary chunks are skipped", 36));
    const std::string stream(reinterpret_cast<const char*>(z.data()), size);
    chunk("IDAT", stream.substr(0, size / 2));
    chunk("IDAT", stream.substr(size / 2));
    chunk("IEND", "");

    TempDir dir;
    const std::string path = dir.file("filtered.png");
    write_file(path, png);
    const Image back = read_png_rgb(path);
    EXPECT_EQ(back.width, w);
    EXPECT_EQ(back.height, h);
    EXPECT_EQ(back.rgb, img.rgb);
}

TEST(Png, BadFilesAreRejected) {
    TempDir dir;
    const std::string path = dir.file("image.png");
    write_png(path, random_image(8, 8, 3));
    const std::string good = read_file(path);

    write_file(path, good.substr(0, good.size() - 20));
    expect_error<std::runtime_error>([&] { read_png_rgb(path); }, path, "truncated");

    std::string corrupt = good;
    corrupt[good.size() - 14] = char(corrupt[good.size() - 14] ^ 0x55);  // the IDAT's CRC (IEND is the last 12 bytes)
    write_file(path, corrupt);
    expect_error<std::runtime_error>([&] { read_png_rgb(path); }, path, "CRC");

    corrupt = good;
    corrupt[good.size() / 2] = char(corrupt[good.size() / 2] ^ 0x55);  // inside the image data
    write_file(path, corrupt);
    expect_error<std::runtime_error>([&] { read_png_rgb(path); }, path, "IDAT");

    write_file(path, "GIF89a not a png");
    expect_error<std::runtime_error>([&] { read_png_rgb(path); }, path, "not a PNG file");

    const std::string missing = dir.file("missing.png");
    expect_error<std::runtime_error>([&] { read_png_rgb(missing); }, missing, "cannot open");
}

// Other encoders' colour types load as RGB (libpng converts them): a greyscale PNG gives
// r = g = b = the grey level.
TEST(Png, ReadsGreyscaleAsRgb) {
    const int w = 5, h = 3;
    std::vector<std::uint8_t> grey(std::size_t(w * h));
    for (std::size_t i = 0; i < grey.size(); ++i) grey[i] = std::uint8_t(17 * i);
    png_image image;
    std::memset(&image, 0, sizeof(image));
    image.version = PNG_IMAGE_VERSION;
    image.width = w;
    image.height = h;
    image.format = PNG_FORMAT_GRAY;
    TempDir dir;
    const std::string path = dir.file("grey.png");
    ASSERT_TRUE(png_image_write_to_file(&image, path.c_str(), 0, grey.data(), 0, nullptr)) << image.message;
    const Image back = read_png_rgb(path);
    ASSERT_EQ(back.width, w);
    ASSERT_EQ(back.height, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const std::uint8_t g = grey[std::size_t(y * w + x)];
            EXPECT_EQ(back.get(x, y), (Rgb{g, g, g})) << x << ", " << y;
        }
}

TEST(Png, WriterRejectsBadImages) {
    TempDir dir;
    const std::string path = dir.file("image.png");
    EXPECT_THROW(write_png(path, Image()), std::invalid_argument);
    Image img(4, 4);
    img.rgb.pop_back();
    EXPECT_THROW(write_png(path, img), std::invalid_argument);
    EXPECT_FALSE(fs::exists(path));
}

TEST(Png, TextChunksRoundTrip) {
    TempDir dir;
    const std::string path = dir.file("tagged.png");
    Image img = random_image(7, 5, 3);
    img.text["pnet_run_id"] = "0123abcd";
    img.text["Comment"] = "two words";
    write_png(path, img);
    const Image back = read_png_rgb(path);
    EXPECT_EQ(back.rgb, img.rgb);
    EXPECT_EQ(back.text, img.text);
    EXPECT_EQ(read_png_text(path), img.text);
    // libpng (the reference decoder) sees the chunks too, with their CRCs valid.
    const std::string bytes = read_file(path);
    EXPECT_NE(bytes.find("tEXtpnet_run_id"), std::string::npos);

    const std::string plain = dir.file("plain.png");
    write_png(plain, random_image(3, 3, 4));
    EXPECT_TRUE(read_png_text(plain).empty());
}

TEST(Png, BadTextIsRejected) {
    TempDir dir;
    const std::string path = dir.file("bad.png");
    Image img = random_image(4, 4, 5);
    img.text[""] = "no keyword";
    expect_error<std::invalid_argument>([&] { write_png(path, img); }, path, "keyword");
    img.text.clear();
    img.text[std::string(80, 'k')] = "too long a keyword";
    expect_error<std::invalid_argument>([&] { write_png(path, img); }, path, "keyword");
    EXPECT_FALSE(fs::exists(path));

    img.text.clear();
    img.text["pnet_run_id"] = "abc";
    write_png(path, img);
    std::string bytes = read_file(path);
    bytes[bytes.find("tEXt") + 6] ^= 0x20;  // a flipped bit in the chunk's data: its CRC no longer matches
    write_file(path, bytes);
    expect_error<std::runtime_error>([&] { read_png_text(path); }, path, "CRC");
    expect_error<std::runtime_error>([&] { read_png_rgb(path); }, path, "CRC");
}

}  // namespace
}  // namespace pnet
