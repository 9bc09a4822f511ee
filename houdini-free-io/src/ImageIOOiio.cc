// Image files through OpenImageIO: the only code in vdbturb that reads or writes pictures. Built as the module
// libturb_oiio.so (ImageBackend.h says why); turb_io loads it on first use.
#include "ImageBackend.h"

#include <turbio/ImageIO.h>
#include <turbio/Vdb.h>

#include <turb/Error.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <sys/stat.h>

namespace turbio {

using turb::IoError;

namespace {

std::string lower(std::string s)
{
    for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

std::string oiioError(const std::string& fallback)
{
    std::string e = OIIO::geterror();
    return e.empty() ? fallback : e;
}

/// A message from OpenImageIO without the file name it often repeats.
std::string clean(std::string msg, const std::string& path)
{
    for (size_t at; !path.empty() && (at = msg.find(path)) != std::string::npos;) msg.erase(at, path.size());
    while (!msg.empty() && (msg.back() == '\n' || msg.back() == ' ')) msg.pop_back();
    const size_t start = msg.find_first_not_of(" :\"\'");
    return start == std::string::npos ? std::string("unknown error") : msg.substr(start);
}

ImageFileInfo infoOf(const std::string& path, const OIIO::ImageInput& in)
{
    const OIIO::ImageSpec& spec = in.spec();
    ImageFileInfo info;
    info.path = path;
    info.format = in.format_name();
    info.width = spec.width;
    info.height = spec.height;
    info.channels = spec.nchannels;
    info.channelNames = spec.channelnames;
    info.hasAlpha = spec.alpha_channel >= 0;
    // Read with the "unassociated" hint: formats that can store straight alpha (PNG, TIFF) hand it over
    // as stored and say so; those that cannot (EXR) are premultiplied.
    info.associatedAlpha = info.hasAlpha && spec.get_int_attribute("oiio:UnassociatedAlpha", 0) == 0;
    info.pixelType = spec.format.c_str();
    info.colorSpace = spec.get_string_attribute("oiio:ColorSpace");
    for (const OIIO::ParamValue& p : spec.extra_attribs)
        if (p.type() == OIIO::TypeDesc::STRING && p.nvalues() == 1)
            info.metadata.emplace_back(p.name().string(), p.get_string());
    return info;
}

std::unique_ptr<OIIO::ImageInput> openInput(const std::string& path)
{
    struct stat st;
    if (::stat(path.c_str(), &st) != 0) throw IoError(path + ": no such file");
    if (!S_ISREG(st.st_mode)) throw IoError(path + ": not a regular file");
    OIIO::ImageSpec config;
    config.attribute("oiio:UnassociatedAlpha", 1);
    auto in = OIIO::ImageInput::open(path, &config);
    if (!in) throw IoError(path + ": cannot read image (" + clean(oiioError("unknown format"), path) + ")");
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) throw IoError(path + ": image has no pixels");
    if (spec.depth > 1) throw IoError(path + ": volume images are not supported");
    if (double(spec.width) * spec.height * spec.nchannels > 2.0e9) throw IoError(path + ": image too large");
    return in;
}

/// Index of the channel called `name` (case-insensitive, also "*.name" as EXR layers write), or -1.
int channelNamed(const OIIO::ImageSpec& spec, const std::string& name)
{
    for (int c = 0; c < spec.nchannels; ++c) {
        const std::string n = lower(spec.channel_name(c));
        const std::string want = lower(name);
        if (n == want ||
            (n.size() > want.size() + 1 && n.compare(n.size() - want.size() - 1, std::string::npos, "." + want) == 0))
            return c;
    }
    return -1;
}

/// Which file channel feeds R, G, B, A (-1 = constant: 0 for colour, 1 for alpha).
std::array<int, 4> channelMap(const OIIO::ImageSpec& spec)
{
    std::array<int, 4> m{channelNamed(spec, "R"), channelNamed(spec, "G"), channelNamed(spec, "B"), spec.alpha_channel};
    if (m[3] < 0) m[3] = channelNamed(spec, "A");
    if (m[0] >= 0 || m[1] >= 0 || m[2] >= 0) return m;
    const int y = channelNamed(spec, "Y");
    if (y >= 0) return {y, y, y, m[3]};
    // No recognised names: by position.
    const int n = spec.nchannels;
    if (n == 1) return {0, 0, 0, -1};
    if (n == 2) return m[3] == 1 ? std::array<int, 4>{0, 0, 0, 1} : std::array<int, 4>{0, 1, -1, -1};
    return {0, 1, 2, n >= 4 ? (m[3] >= 0 ? m[3] : 3) : -1};
}

const char* const kFontFile = "/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf";

std::string captionFont()
{
    struct stat st;
    if (::stat(kFontFile, &st) == 0) return kFontFile;
    return "DejaVuSansMono.ttf"; // searched by OpenImageIO in its font paths
}

/// The picture as a 3-channel float buffer with its captions drawn.
OIIO::ImageBuf pictureBuffer(const turb::Image& picture)
{
    OIIO::ImageBuf buf(OIIO::ImageSpec(picture.width(), picture.height(), 3, OIIO::TypeDesc::FLOAT));
    if (!picture.empty())
        buf.set_pixels(OIIO::ROI(0, picture.width(), 0, picture.height(), 0, 1, 0, 3), OIIO::TypeDesc::FLOAT,
            picture.pixels().data());
    const std::string font = captionFont();
    for (const turb::TextLabel& t : picture.texts()) {
        const float color[3] = {t.color[0], t.color[1], t.color[2]};
        // TextLabel's y is the top of the capitals; render_text's is the baseline (cap height 7/10 em).
        if (!OIIO::ImageBufAlgo::render_text(buf, t.x, t.y + 7 * t.scale, t.text, 10 * t.scale, font, color,
                OIIO::ImageBufAlgo::TextAlignX::Left, OIIO::ImageBufAlgo::TextAlignY::Baseline, 0, {}, 1))
            throw IoError(std::string("cannot draw the caption '") + t.text + "' with " + font + " (" +
                          clean(buf.geterror(), "") + "); install the Debian package fonts-dejavu-core");
    }
    return buf;
}

float srgbToLinear(float v) { return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f); }

OIIO::TypeDesc storageType(const std::string& path, const std::string& format, PixelBits bits)
{
    const auto refuse = [&](const char* what) -> OIIO::TypeDesc {
        throw IoError(path + ": " + format + " cannot store " + what + " pixels");
    };
    switch (bits) {
    case PixelBits::Auto:
        return format == "openexr" ? OIIO::TypeDesc::HALF
               : format == "tiff"  ? OIIO::TypeDesc::UINT16
                                   : OIIO::TypeDesc::UINT8;
    case PixelBits::Uint8: return format == "openexr" ? refuse("8-bit") : OIIO::TypeDesc::UINT8;
    case PixelBits::Uint16: return format == "openexr" || format == "jpeg" ? refuse("16-bit") : OIIO::TypeDesc::UINT16;
    case PixelBits::Half: return format == "openexr" || format == "tiff" ? OIIO::TypeDesc::HALF : refuse("half-float");
    case PixelBits::Float: return format == "openexr" || format == "tiff" ? OIIO::TypeDesc::FLOAT : refuse("float");
    }
    return OIIO::TypeDesc::UINT8;
}

/// Writes interleaved float pixels with `spec` (its format is the storage type) atomically.
void writePixels(const std::string& path, const OIIO::ImageSpec& given, const std::vector<float>& data,
    const ImageWriteOptions& options)
{
    // OIIO's EXR writer stamps the wall-clock time (capDate) when no DateTime is given: the same run would then
    // never give the same bytes twice. The frame's content does not depend on when it was written.
    OIIO::ImageSpec spec = given;
    if (spec.find_attribute("DateTime") == nullptr) spec.attribute("DateTime", "");
    for (const auto& [name, value] : options.metadata) spec.attribute(name, value);
    writeAtomically(path, options.noClobber, [&](const std::string& tmp) {
        // The plugin is chosen by the real name; the temporary name does not end in the extension.
        auto out = OIIO::ImageOutput::create(path);
        if (!out) throw IoError(path + ": cannot write this format (" + clean(oiioError("no writer"), path) + ")");
        if (!out->open(tmp, spec)) throw IoError(path + ": cannot write (" + clean(out->geterror(), tmp) + ")");
        const bool ok = out->write_image(OIIO::TypeDesc::FLOAT, data.data());
        const std::string err = ok ? std::string() : out->geterror();
        if (!out->close() || !ok)
            throw IoError(path + ": write failed (" + clean(err.empty() ? out->geterror() : err, tmp) + ")");
    });
}

ImageFileInfo oiioInspect(const std::string& path)
{
    auto in = openInput(path);
    return infoOf(path, *in);
}

turb::RgbaImage oiioRead(const std::string& path, ImageFileInfo* infoOut)
{
    auto in = openInput(path);
    const ImageFileInfo info = infoOf(path, *in);
    const OIIO::ImageSpec spec = in->spec();
    const int n = spec.nchannels;
    std::vector<float> raw(size_t(spec.width) * size_t(spec.height) * size_t(n));
    if (!in->read_image(0, 0, 0, n, OIIO::TypeDesc::FLOAT, raw.data()))
        throw IoError(path + ": corrupt or truncated image (" + clean(in->geterror(), path) + ")");
    in->close();

    const std::array<int, 4> map = channelMap(spec);
    turb::RgbaImage img(spec.width, spec.height);
    img.colorSpace = info.colorSpace;
    for (size_t p = 0; p < img.size(); ++p) {
        const float* src = &raw[p * size_t(n)];
        turb::Rgba v;
        for (int c = 0; c < 4; ++c) v[c] = map[size_t(c)] >= 0 ? src[map[size_t(c)]] : (c == 3 ? 1.0f : 0.0f);
        if (info.associatedAlpha && v[3] > 0.0f)
            for (int c = 0; c < 3; ++c) v[c] /= v[3];
        img.pixels()[p] = v;
    }
    if (infoOut) *infoOut = info;
    return img;
}

void oiioWriteRgba(const std::string& path, const turb::RgbaImage& image, const ImageWriteOptions& options)
{
    const std::string format = outputFormatOf(path);
    if (image.empty()) throw IoError(path + ": cannot write an empty image");
    const bool alpha = options.alpha && format != "jpeg";
    const int nc = alpha ? 4 : 3;
    OIIO::ImageSpec spec(image.width(), image.height(), nc, storageType(path, format, options.bits));
    if (alpha) {
        spec.alpha_channel = 3;
        // Straight alpha where the format can say so; EXR is premultiplied by definition.
        if (format != "openexr") spec.attribute("oiio:UnassociatedAlpha", 1);
    }
    if (!image.colorSpace.empty()) spec.attribute("oiio:ColorSpace", image.colorSpace);
    if (format == "openexr") spec.attribute("compression", "zip");
    std::vector<float> data(image.size() * size_t(nc));
    for (size_t p = 0; p < image.size(); ++p) {
        const turb::Rgba& v = image.pixels()[p];
        const float a = alpha && format == "openexr" ? v[3] : 1.0f;
        for (int c = 0; c < 3; ++c) data[p * size_t(nc) + size_t(c)] = v[c] * a;
        if (alpha) data[p * size_t(nc) + 3] = v[3];
    }
    writePixels(path, spec, data, options);
}

void oiioWritePicture(const std::string& path, const turb::Image& picture, const ImageWriteOptions& options)
{
    const std::string format = outputFormatOf(path);
    if (picture.empty()) throw IoError(path + ": cannot write an empty image");
    OIIO::ImageBuf buf = pictureBuffer(picture);
    std::vector<float> data(size_t(picture.width()) * size_t(picture.height()) * 3);
    buf.get_pixels(OIIO::ROI(0, picture.width(), 0, picture.height(), 0, 1, 0, 3), OIIO::TypeDesc::FLOAT, data.data());
    const bool linear = format == "openexr";
    for (float& v : data) {
        v = std::isfinite(v) ? std::min(1.0f, std::max(0.0f, v)) : 0.0f;
        if (linear) v = srgbToLinear(v);
    }
    OIIO::ImageSpec spec(picture.width(), picture.height(), 3, storageType(path, format, options.bits));
    spec.attribute("oiio:ColorSpace", linear ? "Linear" : "sRGB");
    if (linear) spec.attribute("compression", "zip");
    writePixels(path, spec, data, options);
}

turb::Image oiioTextDrawn(const turb::Image& picture)
{
    if (picture.texts().empty() || picture.empty()) {
        turb::Image copy = picture;
        copy.clearTexts();
        return copy;
    }
    OIIO::ImageBuf buf = pictureBuffer(picture);
    turb::Image out(picture.width(), picture.height());
    buf.get_pixels(
        OIIO::ROI(0, picture.width(), 0, picture.height(), 0, 1, 0, 3), OIIO::TypeDesc::FLOAT, out.pixels().data());
    return out;
}

} // namespace

} // namespace turbio

extern "C" const turbio::detail::ImageBackend* vdbturb_oiio_backend()
{
    static const turbio::detail::ImageBackend table{
        turbio::oiioInspect, turbio::oiioRead, turbio::oiioWriteRgba, turbio::oiioWritePicture, turbio::oiioTextDrawn};
    return &table;
}
