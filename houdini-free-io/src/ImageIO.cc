// turbio/ImageIO.h without OpenImageIO: output formats by extension, and the module (libturb_oiio.so,
// ImageBackend.h) that does the reading and writing, loaded on the first call that needs it.
#include "ImageBackend.h"

#include <turb/Error.h>

#include <algorithm>
#include <cctype>
#include <dlfcn.h>
#include <string>
#include <vector>

namespace turbio {

namespace {

std::string extensionOf(const std::string& path)
{
    const size_t slash = path.find_last_of('/');
    const size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot + 1);
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

// Where the module may be: beside the library holding this code (the build tree, or an install prefix moved
// as a whole), then the configured install and build directories (a static turb_io has no directory of its own).
std::vector<std::string> moduleCandidates()
{
    std::vector<std::string> out;
    Dl_info self{};
    if (::dladdr(reinterpret_cast<void*>(&moduleCandidates), &self) && self.dli_fname) {
        const std::string lib = self.dli_fname;
        const size_t slash = lib.find_last_of('/');
        if (slash != std::string::npos) out.push_back(lib.substr(0, slash + 1) + VDBTURB_OIIO_MODULE);
    }
    for (const char* dir : {VDBTURB_OIIO_INSTALL_DIR, VDBTURB_OIIO_BUILD_DIR}) {
        const std::string path = std::string(dir) + "/" + VDBTURB_OIIO_MODULE;
        if (std::find(out.begin(), out.end(), path) == out.end()) out.push_back(path);
    }
    return out;
}

const detail::ImageBackend* loadBackend()
{
    std::string tried;
    for (const std::string& path : moduleCandidates()) {
        // RTLD_GLOBAL: OpenImageIO's own plugins and the codecs resolve against what it loaded.
        if (void* h = ::dlopen(path.c_str(), RTLD_NOW | RTLD_GLOBAL)) {
            using Entry = const detail::ImageBackend* (*)();
            if (auto entry = reinterpret_cast<Entry>(::dlsym(h, "vdbturb_oiio_backend"))) return entry();
            tried += "\n  " + path + ": no vdbturb_oiio_backend";
            continue;
        }
        const char* e = ::dlerror(); // names the path
        tried += "\n  " + (e ? std::string(e) : path + ": cannot load");
    }
    throw turb::IoError(std::string("image IO is not available: OpenImageIO's module ") + VDBTURB_OIIO_MODULE +
                        " could not be loaded (reinstall vdbturb, or install libopenimageio):" + tried);
}

const detail::ImageBackend& backend()
{
    static const detail::ImageBackend* b = loadBackend(); // once; a failure throws and is retried next call
    return *b;
}

} // namespace

std::string outputFormatOf(const std::string& path)
{
    const std::string ext = extensionOf(path);
    if (ext == "png") return "png";
    if (ext == "exr") return "openexr";
    if (ext == "tif" || ext == "tiff") return "tiff";
    if (ext == "jpg" || ext == "jpeg") return "jpeg";
    throw turb::ValueError(path + ": unknown image extension '" + ext + "' (write .png, .exr, .tif or .jpg)");
}

ImageFileInfo inspectImage(const std::string& path) { return backend().inspectImage(path); }

std::string ImageFileInfo::attribute(const std::string& name) const
{
    for (const auto& [key, value] : metadata)
        if (key == name) return value;
    return {};
}

turb::RgbaImage readImage(const std::string& path, ImageFileInfo* info) { return backend().readImage(path, info); }

void writeImage(const std::string& path, const turb::RgbaImage& image, const ImageWriteOptions& options)
{
    backend().writeRgba(path, image, options);
}

void writeImage(const std::string& path, const turb::Image& picture, const ImageWriteOptions& options)
{
    backend().writePicture(path, picture, options);
}

turb::Image withTextDrawn(const turb::Image& picture) { return backend().withTextDrawn(picture); }

} // namespace turbio
