#include "pnet/io/png.hpp"

#include <png.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>

#include "pnet/io/atomic_file.hpp"

namespace pnet {

namespace {

constexpr std::size_t kSignatureBytes = 8;
constexpr std::size_t kIhdrChunkBytes = 4 + 4 + 13 + 4;  // length, type, data, CRC

std::uint32_t big_endian_u32(const std::string& bytes, std::size_t at) {
    std::uint32_t v = 0;
    for (int k = 0; k < 4; ++k) v = (v << 8) | static_cast<unsigned char>(bytes[at + k]);
    return v;
}

std::string big_endian_bytes(std::uint32_t v) {
    return {char(v >> 24), char((v >> 16) & 0xff), char((v >> 8) & 0xff), char(v & 0xff)};
}

/// One PNG chunk: length, type, data, CRC-32 of type and data.
std::string png_chunk(const std::string& type, const std::string& data) {
    const std::string body = type + data;
    const auto crc = std::uint32_t(crc32(crc32(0L, Z_NULL, 0), reinterpret_cast<const Bytef*>(body.data()),
                                         static_cast<uInt>(body.size())));
    return big_endian_bytes(std::uint32_t(data.size())) + body + big_endian_bytes(crc);
}

/// The tEXt chunks of a PNG's bytes before its first IDAT; `fail` makes the error to throw.
template <class Fail>
std::map<std::string, std::string> text_chunks(const std::string& bytes, const Fail& fail) {
    std::map<std::string, std::string> text;
    std::size_t at = kSignatureBytes;
    while (true) {
        if (bytes.size() - at < 12) throw fail("corrupt or truncated PNG (a chunk runs past the end)");
        const std::uint32_t length = big_endian_u32(bytes, at);
        if (length > bytes.size() - at - 12) throw fail("corrupt or truncated PNG (a chunk runs past the end)");
        const std::string type = bytes.substr(at + 4, 4);
        if (type == "IDAT" || type == "IEND") return text;
        const std::string body = bytes.substr(at + 4, 4 + std::size_t(length));
        const auto crc = std::uint32_t(crc32(crc32(0L, Z_NULL, 0), reinterpret_cast<const Bytef*>(body.data()),
                                             static_cast<uInt>(body.size())));
        if (crc != big_endian_u32(bytes, at + 8 + length))
            throw fail("corrupt PNG (bad CRC in the " + type + " chunk)");
        if (type == "tEXt") {
            const std::string data = body.substr(4);
            const std::size_t nul = data.find('\0');
            if (nul == std::string::npos || nul == 0) throw fail("corrupt PNG (a tEXt chunk without a keyword)");
            text[data.substr(0, nul)] = data.substr(nul + 1);
        }
        at += 12 + std::size_t(length);
    }
}

// Far above any frame or plot, and low enough that 3 * w * h cannot overflow anywhere or make a
// corrupt header allocate gigabytes.
constexpr std::int64_t kMaxPixels = std::int64_t(1) << 28;

/// libpng's simplified API (png_image) owns its state through `opaque`; this frees it on
/// every path out, errors included.
struct PngImage {
    png_image image;
    PngImage() {
        std::memset(&image, 0, sizeof(image));
        image.version = PNG_IMAGE_VERSION;
    }
    ~PngImage() { png_image_free(&image); }
    PngImage(const PngImage&) = delete;
    PngImage& operator=(const PngImage&) = delete;
};

}  // namespace

Image::Image(int width_, int height_, Rgb background) : width(width_), height(height_) {
    if (width < 0 || height < 0 || std::int64_t(width) * height > kMaxPixels) {
        throw std::invalid_argument("Image: bad size " + std::to_string(width) + " x " + std::to_string(height));
    }
    rgb.resize(std::size_t(3) * std::size_t(width) * std::size_t(height));
    fill(background);
}

Rgb Image::get(int x, int y) const {
    const std::size_t i = 3 * (std::size_t(y) * std::size_t(width) + std::size_t(x));
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
}

void Image::set(int x, int y, Rgb c) {
    if (!contains(x, y)) return;
    const std::size_t i = 3 * (std::size_t(y) * std::size_t(width) + std::size_t(x));
    rgb[i] = c.r;
    rgb[i + 1] = c.g;
    rgb[i + 2] = c.b;
}

void Image::blend(int x, int y, Rgb c, double alpha) {
    if (!contains(x, y) || !(alpha > 0.0)) return;
    if (alpha >= 1.0) return set(x, y, c);
    const std::size_t i = 3 * (std::size_t(y) * std::size_t(width) + std::size_t(x));
    const std::uint8_t src[3] = {c.r, c.g, c.b};
    for (int k = 0; k < 3; ++k) {
        rgb[i + k] = std::uint8_t(std::lround((1.0 - alpha) * rgb[i + k] + alpha * src[k]));
    }
}

void Image::fill(Rgb c) {
    for (std::size_t i = 0; i + 2 < rgb.size(); i += 3) {
        rgb[i] = c.r;
        rgb[i + 1] = c.g;
        rgb[i + 2] = c.b;
    }
}

void write_png(const std::string& path, const Image& img) {
    if (img.width <= 0 || img.height <= 0 || std::int64_t(img.width) * img.height > kMaxPixels) {
        throw std::invalid_argument(path + ": cannot write a " + std::to_string(img.width) + " x " +
                                    std::to_string(img.height) + " image as PNG");
    }
    const std::size_t row_bytes = 3 * std::size_t(img.width);
    if (img.rgb.size() != row_bytes * std::size_t(img.height)) {
        throw std::invalid_argument(path + ": image has " + std::to_string(img.rgb.size()) + " bytes, expected " +
                                    std::to_string(row_bytes * std::size_t(img.height)));
    }
    PngImage png;
    png.image.width = png_uint_32(img.width);
    png.image.height = png_uint_32(img.height);
    png.image.format = PNG_FORMAT_RGB;
    // Encode to memory first (size query, then the bytes), so that the file is written whole
    // and atomically: a failed encode leaves any earlier file untouched.
    png_alloc_size_t size = 0;
    if (!png_image_write_to_memory(&png.image, nullptr, &size, 0, img.rgb.data(), 0, nullptr))
        throw std::runtime_error(path + ": libpng cannot encode the image: " + png.image.message);
    std::string bytes(size, '\0');
    if (!png_image_write_to_memory(&png.image, bytes.data(), &size, 0, img.rgb.data(), 0, nullptr))
        throw std::runtime_error(path + ": libpng cannot encode the image: " + png.image.message);
    bytes.resize(size);
    // tEXt chunks go right after IHDR (8 signature bytes + 25 bytes of IHDR chunk).
    std::string text_chunks;
    for (const auto& [keyword, text] : img.text) {
        const bool printable = std::all_of(keyword.begin(), keyword.end(), [](char ch) {
            const auto u = static_cast<unsigned char>(ch);
            return (u >= 32 && u <= 126) || u >= 161;
        });
        if (keyword.empty() || keyword.size() > 79 || !printable || keyword.front() == ' ' || keyword.back() == ' ' ||
            text.find('\0') != std::string::npos)
            throw std::invalid_argument(path + ": PNG text keyword '" + keyword +
                                        "': expected 1-79 printable characters and a text without NUL");
        text_chunks += png_chunk("tEXt", keyword + '\0' + text);
    }
    bytes.insert(kSignatureBytes + kIhdrChunkBytes, text_chunks);
    write_text_atomically(path, bytes);
}

namespace {

/// The bytes of a PNG in memory, handed to libpng's reader in the pieces it asks for.
struct MemorySource {
    const std::string& bytes;
    std::size_t position = 0;
};

void read_from_memory(png_structp png, png_bytep out, png_size_t size) {
    auto* source = static_cast<MemorySource*>(png_get_io_ptr(png));
    if (size > source->bytes.size() - source->position) png_error(png, "truncated file (read beyond its end)");
    std::memcpy(out, source->bytes.data() + source->position, size);
    source->position += size;
}

/// libpng reports errors by longjmp; the message is kept here for the exception thrown after.
void record_error(png_structp png, png_const_charp message) {
    *static_cast<std::string*>(png_get_error_ptr(png)) = message;
    png_longjmp(png, 1);
}

void ignore_warning(png_structp, png_const_charp) {}

/// The whole file, checked to start with the PNG signature.
std::string read_png_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot open for reading: " + std::strerror(errno));
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) throw std::runtime_error(path + ": reading failed");
    if (bytes.size() < 8 || png_sig_cmp(reinterpret_cast<png_const_bytep>(bytes.data()), 0, 8) != 0)
        throw std::runtime_error(path + ": not a PNG file (bad signature)");
    return bytes;
}

}  // namespace

Image read_png_rgb(const std::string& path) {
    const std::string bytes = read_png_bytes(path);
    auto fail = [&](const std::string& problem) { return std::runtime_error(path + ": " + problem); };
    std::map<std::string, std::string> text = text_chunks(bytes, fail);

    // libpng's full reader, not png_image: that one skips the chunk CRCs of the image data.
    std::string error;
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &error, record_error, ignore_warning);
    if (!png) throw fail("libpng cannot allocate a reader");
    png_infop info = png_create_info_struct(png);
    MemorySource source{bytes, 0};
    // libpng longjmps to the last setjmp on an error. Locals with destructors are made outside
    // the guarded stretches, which change only libpng's state and the pixels behind `rows`.
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, nullptr);
        throw fail("corrupt or truncated PNG (libpng: " + error + ")");
    }
    if (!info) png_error(png, "cannot allocate the info struct");
    png_set_read_fn(png, &source, read_from_memory);
    png_set_crc_action(png, PNG_CRC_ERROR_QUIT, PNG_CRC_WARN_DISCARD);  // critical chunks: a bad CRC is an error
    png_read_info(png, info);
    const png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    if (w == 0 || h == 0 || std::int64_t(w) * std::int64_t(h) > kMaxPixels) {
        png_destroy_read_struct(&png, &info, nullptr);
        throw fail("unsupported image size " + std::to_string(w) + " x " + std::to_string(h));
    }
    // Any PNG loads as 8-bit RGB: palette and grey expanded, 16-bit stripped, alpha composited on white.
    const int colour = png_get_color_type(png, info);
    if (colour == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    if (colour == PNG_COLOR_TYPE_GRAY || colour == PNG_COLOR_TYPE_GRAY_ALPHA) png_set_gray_to_rgb(png);
    if (png_get_bit_depth(png, info) < 8) png_set_expand(png);
    png_set_strip_16(png);
    if (colour & PNG_COLOR_MASK_ALPHA || png_get_valid(png, info, PNG_INFO_tRNS)) {
        png_color_16 white{};
        white.red = white.green = white.blue = white.gray = 255;
        png_set_background(png, &white, PNG_BACKGROUND_GAMMA_SCREEN, 0, 1.0);
    }
    png_set_interlace_handling(png);
    png_read_update_info(png, info);

    Image img{int(w), int(h)};
    img.text = std::move(text);
    std::vector<png_bytep> rows(h);
    for (png_uint_32 y = 0; y < h; ++y) rows[y] = img.rgb.data() + std::size_t(y) * 3 * w;
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, nullptr);
        throw fail("corrupt or truncated PNG (libpng: " + error + ")");
    }
    png_read_image(png, rows.data());
    png_read_end(png, nullptr);
    png_destroy_read_struct(&png, &info, nullptr);
    return img;
}

std::map<std::string, std::string> read_png_text(const std::string& path) {
    return text_chunks(read_png_bytes(path), [&](const std::string& problem) {
        return std::runtime_error(path + ": " + problem);
    });
}

}  // namespace pnet
