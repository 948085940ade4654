#include "pnet/io/png.hpp"

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

constexpr std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

// Far above any frame or plot, and low enough that 3 * w * h + h cannot overflow anywhere or
// make a corrupt header allocate gigabytes.
constexpr std::int64_t kMaxPixels = std::int64_t(1) << 28;

void put_be32(std::string& out, std::uint32_t v) {
    out.push_back(static_cast<char>(v >> 24));
    out.push_back(static_cast<char>((v >> 16) & 0xff));
    out.push_back(static_cast<char>((v >> 8) & 0xff));
    out.push_back(static_cast<char>(v & 0xff));
}

std::uint32_t get_be32(const std::uint8_t* p) {
    return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) | p[3];
}

// A chunk is length, type, data, and the CRC-32 of type + data (PNG spec section 5.3).
void put_chunk(std::string& out, const char type[4], const std::uint8_t* data, std::size_t size) {
    put_be32(out, std::uint32_t(size));
    out.append(type, 4);
    out.append(reinterpret_cast<const char*>(data), size);
    uLong crc = crc32(0L, Z_NULL, 0);
    crc = crc32(crc, reinterpret_cast<const Bytef*>(type), 4);
    if (size > 0) crc = crc32_z(crc, data, size);
    put_be32(out, std::uint32_t(crc));
}

// Paeth predictor (PNG spec section 9.4).
std::uint8_t paeth(int a, int b, int c) {
    const int p = a + b - c;
    const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
    if (pa <= pb && pa <= pc) return std::uint8_t(a);
    return std::uint8_t(pb <= pc ? b : c);
}

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

    // Filter type 0 (None) on every row: each scanline is its filter byte then the raw pixels.
    std::vector<std::uint8_t> raw((row_bytes + 1) * std::size_t(img.height));
    for (int y = 0; y < img.height; ++y) {
        std::uint8_t* dst = &raw[std::size_t(y) * (row_bytes + 1)];
        dst[0] = 0;
        std::memcpy(dst + 1, &img.rgb[std::size_t(y) * row_bytes], row_bytes);
    }
    uLongf compressed_size = compressBound(uLong(raw.size()));
    std::vector<std::uint8_t> compressed(compressed_size);
    const int status = compress2(compressed.data(), &compressed_size, raw.data(), uLong(raw.size()), 6);
    if (status != Z_OK) throw std::runtime_error(path + ": zlib compress2 failed (" + std::to_string(status) + ")");

    std::string png(reinterpret_cast<const char*>(kSignature), sizeof(kSignature));
    std::string ihdr;
    put_be32(ihdr, std::uint32_t(img.width));
    put_be32(ihdr, std::uint32_t(img.height));
    ihdr += std::string{8, 2, 0, 0, 0};  // bit depth 8, colour type 2 (RGB), deflate, filter set 0, no interlace
    put_chunk(png, "IHDR", reinterpret_cast<const std::uint8_t*>(ihdr.data()), ihdr.size());
    put_chunk(png, "IDAT", compressed.data(), compressed_size);
    put_chunk(png, "IEND", nullptr, 0);
    write_text_atomically(path, png);
}

Image read_png_rgb(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot open for reading: " + std::strerror(errno));
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) throw std::runtime_error(path + ": reading failed");
    auto fail = [&](const std::string& problem) { return std::runtime_error(path + ": " + problem); };
    const auto* data = reinterpret_cast<const std::uint8_t*>(bytes.data());

    if (bytes.size() < sizeof(kSignature) || std::memcmp(data, kSignature, sizeof(kSignature)) != 0) {
        throw fail("not a PNG file (bad signature)");
    }
    std::size_t pos = sizeof(kSignature);
    int width = 0, height = 0;
    bool have_header = false, ended = false;
    std::vector<std::uint8_t> idat;
    while (!ended) {
        if (bytes.size() - pos < 12) throw fail("truncated PNG (chunk header at byte " + std::to_string(pos) + ")");
        const std::uint32_t length = get_be32(data + pos);
        const std::string type(bytes, pos + 4, 4);
        if (length > bytes.size() - pos - 12) throw fail("truncated PNG (" + type + " chunk)");
        const std::uint8_t* body = data + pos + 8;
        uLong crc = crc32(0L, Z_NULL, 0);
        crc = crc32_z(crc, data + pos + 4, 4 + std::size_t(length));
        if (std::uint32_t(crc) != get_be32(body + length)) throw fail("CRC mismatch in the " + type + " chunk");
        pos += 12 + std::size_t(length);

        if (type == "IHDR") {
            if (have_header || length != 13) throw fail("bad IHDR chunk");
            const std::uint32_t w = get_be32(body), h = get_be32(body + 4);
            if (w == 0 || h == 0 || w > std::uint32_t(kMaxPixels) || h > std::uint32_t(kMaxPixels) ||
                std::int64_t(w) * std::int64_t(h) > kMaxPixels) {
                throw fail("unsupported image size " + std::to_string(w) + " x " + std::to_string(h));
            }
            if (body[8] != 8 || body[9] != 2 || body[10] != 0 || body[11] != 0 || body[12] != 0) {
                throw fail("only 8-bit RGB non-interlaced PNG is supported (bit depth " + std::to_string(body[8]) +
                           ", colour type " + std::to_string(body[9]) + ", interlace " + std::to_string(body[12]) +
                           ")");
            }
            width = int(w);
            height = int(h);
            have_header = true;
        } else if (!have_header) {
            throw fail("the first chunk is " + type + ", not IHDR");
        } else if (type == "IDAT") {
            idat.insert(idat.end(), body, body + length);
        } else if (type == "IEND") {
            ended = true;
        } else if (!(type[0] & 0x20) && type != "PLTE") {
            // Bit 5 of the first letter clear marks a critical chunk, which a decoder must not skip.
            throw fail("unsupported critical chunk " + type);
        }
    }
    if (idat.empty()) throw fail("no IDAT chunk");

    const std::size_t row_bytes = 3 * std::size_t(width);
    std::vector<std::uint8_t> raw((row_bytes + 1) * std::size_t(height));
    uLongf raw_size = uLongf(raw.size());
    const int status = uncompress(raw.data(), &raw_size, idat.data(), uLong(idat.size()));
    if (status != Z_OK || raw_size != raw.size()) {
        throw fail("corrupt image data (zlib status " + std::to_string(status) + ", " + std::to_string(raw_size) +
                   " of " + std::to_string(raw.size()) + " bytes)");
    }

    // Undo the row filters (PNG spec section 9.2); bpp = 3 bytes per pixel.
    Image img(width, height);
    std::vector<std::uint8_t> previous(row_bytes, 0), current(row_bytes);
    for (int y = 0; y < height; ++y) {
        const std::uint8_t* line = &raw[std::size_t(y) * (row_bytes + 1)];
        const std::uint8_t filter = line[0];
        for (std::size_t i = 0; i < row_bytes; ++i) {
            const int a = i >= 3 ? current[i - 3] : 0, b = previous[i], c = i >= 3 ? previous[i - 3] : 0;
            int predictor = 0;
            switch (filter) {
                case 0:
                    predictor = 0;
                    break;
                case 1:
                    predictor = a;
                    break;
                case 2:
                    predictor = b;
                    break;
                case 3:
                    predictor = (a + b) / 2;
                    break;
                case 4:
                    predictor = paeth(a, b, c);
                    break;
                default:
                    throw fail("bad filter type " + std::to_string(filter) + " on row " + std::to_string(y));
            }
            current[i] = std::uint8_t(line[1 + i] + predictor);
        }
        std::memcpy(&img.rgb[std::size_t(y) * row_bytes], current.data(), row_bytes);
        std::swap(previous, current);
    }
    return img;
}

}  // namespace pnet
