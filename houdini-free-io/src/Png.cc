#include <turbio/Png.h>
#include <turbio/Vdb.h>

#include <turb/Error.h>

#include <png.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

namespace turbio {

void writePng(const std::string& path, const turb::Image& image, bool noClobber)
{
    if (image.empty()) throw turb::IoError(path + ": cannot write an empty image");
    std::vector<unsigned char> rgb(size_t(image.width()) * size_t(image.height()) * 3);
    for (size_t i = 0; i < image.pixels().size(); ++i)
        for (int c = 0; c < 3; ++c) {
            const float v = image.pixels()[i][c];
            const float cl = std::isfinite(v) ? std::min(1.0f, std::max(0.0f, v)) : 0.0f;
            rgb[i * 3 + size_t(c)] = static_cast<unsigned char>(std::lround(cl * 255.0f));
        }
    png_image img;
    std::memset(&img, 0, sizeof(img));
    img.version = PNG_IMAGE_VERSION;
    img.width = png_uint_32(image.width());
    img.height = png_uint_32(image.height());
    img.format = PNG_FORMAT_RGB;
    png_alloc_size_t size = 0;
    if (!png_image_write_to_memory(&img, nullptr, &size, 0, rgb.data(), 0, nullptr))
        throw turb::IoError(path + ": PNG encoding failed (" + std::string(img.message) + ")");
    std::string bytes(size, '\0');
    if (!png_image_write_to_memory(&img, &bytes[0], &size, 0, rgb.data(), 0, nullptr))
        throw turb::IoError(path + ": PNG encoding failed (" + std::string(img.message) + ")");
    bytes.resize(size);
    writeFileAtomic(path, bytes, noClobber);
}

turb::Image readPng(const std::string& path)
{
    png_image img;
    std::memset(&img, 0, sizeof(img));
    img.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_file(&img, path.c_str()))
        throw turb::IoError(path + ": cannot read PNG (" + std::string(img.message) + ")");
    // 16-bit files keep their precision through the linear format; 8-bit files are read as stored.
    const bool wide = (img.format & PNG_FORMAT_FLAG_LINEAR) != 0;
    img.format = wide ? PNG_FORMAT_LINEAR_RGB : PNG_FORMAT_RGB;
    const size_t n = size_t(img.width) * size_t(img.height) * 3;
    turb::Image out(int(img.width), int(img.height));
    if (wide) {
        std::vector<png_uint_16> buf(n);
        if (!png_image_finish_read(&img, nullptr, buf.data(), 0, nullptr))
            throw turb::IoError(path + ": corrupt PNG (" + std::string(img.message) + ")");
        for (size_t i = 0; i < n / 3; ++i)
            for (int c = 0; c < 3; ++c) out.pixels()[i][c] = float(buf[i * 3 + size_t(c)]) / 65535.0f;
    } else {
        std::vector<unsigned char> buf(n);
        if (!png_image_finish_read(&img, nullptr, buf.data(), 0, nullptr))
            throw turb::IoError(path + ": corrupt PNG (" + std::string(img.message) + ")");
        for (size_t i = 0; i < n / 3; ++i)
            for (int c = 0; c < 3; ++c) out.pixels()[i][c] = float(buf[i * 3 + size_t(c)]) / 255.0f;
    }
    return out;
}

} // namespace turbio
