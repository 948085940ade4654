#pragma once
// A minimal 8-bit RGB raster and its PNG encoding (ISO/IEC 15948), written
// chunk by chunk with zlib for the deflate stream and the CRCs, so that frames
// and plots need no imaging library.
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace pnet {

struct Rgb {
    std::uint8_t r = 0, g = 0, b = 0;
};

inline bool operator==(Rgb a, Rgb b) {
    return a.r == b.r && a.g == b.g && a.b == b.b;
}
inline bool operator!=(Rgb a, Rgb b) {
    return !(a == b);
}

/// Row-major 8-bit RGB image; row 0 is the top row, as in PNG. Pixel writes outside the image
/// are ignored (clipped), so that shapes at the border need no bounds checks by the caller.
struct Image {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb;  // 3 * width * height bytes
    /// Text attached to the file as PNG tEXt chunks, keyword -> text (e.g. the run that wrote a
    /// frame); keywords are 1-79 printable Latin-1 characters, texts have no NUL.
    std::map<std::string, std::string> text;

    Image() = default;
    Image(int width, int height, Rgb background = {255, 255, 255});

    bool contains(int x, int y) const { return x >= 0 && y >= 0 && x < width && y < height; }

    /// Colour at (x, y); (x, y) must be inside the image.
    Rgb get(int x, int y) const;

    void set(int x, int y, Rgb c);

    /// Source-over compositing: pixel = (1 - alpha) pixel + alpha c, alpha clamped to [0, 1]
    /// (used for anti-aliased edges, where alpha is the covered fraction of the pixel).
    void blend(int x, int y, Rgb c, double alpha);

    void fill(Rgb c);
};

/// Writes img atomically (write_file_atomically) as a non-interlaced 8-bit RGB PNG: IHDR, a tEXt
/// chunk per entry of img.text, the image data, IEND. Throws std::invalid_argument
/// "<path>: ..." for an empty image or a pixel buffer of the wrong size, std::runtime_error
/// "<path>: ..." if compression or writing fails.
void write_png(const std::string& path, const Image& img);

/// Reads an 8-bit RGB, non-interlaced PNG, such as write_png() writes (all five row filter
/// types are undone, so files from other encoders of that format load too). Chunk CRCs are
/// checked. Throws std::runtime_error "<path>: <problem>" for anything else (palette, alpha,
/// 16-bit, interlaced, corrupt or truncated). The tEXt chunks before the image data fill text.
Image read_png_rgb(const std::string& path);

/// Only the tEXt chunks before the image data, without decoding the pixels (checks the
/// signature and each chunk's CRC up to the first IDAT; the same errors as read_png_rgb()).
std::map<std::string, std::string> read_png_text(const std::string& path);

}  // namespace pnet
