// Pictures (Image.h, RgbaImage.h) and their files through OpenImageIO (turbio/ImageIO.h): captions, round trips,
// errors.
#include "TestUtil.h"

#include <turb/Error.h>
#include <turb/Image.h>
#include <turb/RgbaImage.h>
#include <turbio/ImageIO.h>

#include <cmath>
#include <fstream>
#include <string>

using namespace turb;

namespace {

bool openImageIoLoaded()
{
    std::ifstream maps("/proc/self/maps");
    for (std::string line; std::getline(maps, line);)
        if (line.find("libOpenImageIO.so") != std::string::npos) return true;
    return false;
}

} // namespace

// First in the file, so that it also holds when the whole binary runs in one process.
TEST(ImageIo, OpenImageIoLoadsOnFirstUseOnly)
{
    // Its ~240 libraries cost 0.5 s of dynamic linking: a command that reads no image must not load them.
    EXPECT_FALSE(openImageIoLoaded());
    EXPECT_EQ(turbio::outputFormatOf("a/b.EXR"), "openexr"); // by extension, no OpenImageIO needed
    EXPECT_FALSE(openImageIoLoaded());
    const testutil::TempDir dir;
    const std::string path = dir / "one.png";
    turbio::writeImage(path, RgbaImage(2, 2));
    EXPECT_TRUE(openImageIoLoaded());
    EXPECT_EQ(turbio::inspectImage(path).width, 2);
}

TEST(Image, CaptionsAreLabelsDrawnByTheIoLayer)
{
    Image a(40, 30, Rgb(0.2f)), b(20, 30, Rgb(0.8f));
    EXPECT_EQ(a.drawText(2, 2, "Ab1", Rgb(1.0f)), Image::textWidth("Ab1"));
    EXPECT_EQ(Image::textWidth("Ab1", 2), 36);
    ASSERT_EQ(a.texts().size(), 1u);
    EXPECT_EQ(a.at(3, 4), Rgb(0.2f)) << "libturb keeps captions as labels, not pixels";
    // Drawn with OpenImageIO's render_text: ink (anti-aliased, so compared with a tolerance) inside the
    // caption's box, none far from it, and the background untouched elsewhere.
    const Image drawn = turbio::withTextDrawn(a);
    EXPECT_TRUE(drawn.texts().empty());
    float inkInside = 0.0f, inkOutside = 0.0f;
    for (int y = 0; y < a.height(); ++y)
        for (int x = 0; x < a.width(); ++x) {
            const float ink = drawn.at(x, y).x() - 0.2f;
            ASSERT_GE(ink, -1e-5f);
            const bool inBox = x >= 1 && x <= 2 + Image::textWidth("Ab1") && y >= 1 && y <= 2 + 7 + 3;
            (inBox ? inkInside : inkOutside) += ink;
        }
    EXPECT_GT(inkInside, 8.0f) << "three glyphs of about 20 inked pixels each";
    EXPECT_LT(inkOutside, 0.05f * inkInside);

    // Captions move with blit and scale with upscaled.
    Image big(100, 100);
    big.blit(a, 10, 20);
    ASSERT_EQ(big.texts().size(), 1u);
    EXPECT_EQ(big.texts()[0].x, 12);
    EXPECT_EQ(big.texts()[0].y, 22);
    EXPECT_EQ(a.upscaled(3).texts()[0].scale, 3);

    const Image sheet = contactSheet({{{&a, "target"}, {&b, "source"}}}, {"f1"}, "title", 1);
    EXPECT_GT(sheet.width(), 60);
    EXPECT_GT(sheet.height(), 30);

    // A caption longer than its cell wraps inside the cell's column: the neighbour's column below the
    // pictures stays background, and the sheet grows taller instead.
    const Image wrapped =
        turbio::withTextDrawn(contactSheet({{{&b, "alpha 0.004 vorticity 0-403/s"}, {&b, ""}}}, {}, "", 1));
    const Image single = contactSheet({{{&b, "a"}, {&b, ""}}}, {}, "", 1);
    EXPECT_GT(wrapped.height(), single.height());
    const int pad = 6, secondX = pad + (b.width() + pad);
    for (int y = 30 + pad; y < wrapped.height(); ++y)
        for (int x = secondX - pad / 2 + 1; x < wrapped.width(); ++x)
            ASSERT_NEAR((wrapped.at(x, y) - Rgb(0.12f)).length(), 0.0f, 0.02f) << x << "," << y;
}

TEST(Image, RoundTripsThroughPngExrTiffAndJpeg)
{
    testutil::TempDir dir;
    Image grad(17, 9);
    for (int y = 0; y < 9; ++y)
        for (int x = 0; x < 17; ++x) grad.at(x, y) = Rgb(x / 16.0f, y / 8.0f, 0.5f);
    for (const char* name : {"g.png", "g.exr", "g.tif"}) {
        turbio::writeImage(dir / name, grad);
        const RgbaImage back = turbio::readImage(dir / name);
        ASSERT_EQ(back.width(), 17) << name;
        ASSERT_EQ(back.height(), 9) << name;
        const bool exr = std::string(name) == "g.exr";
        for (size_t i = 0; i < grad.pixels().size(); ++i)
            for (int c = 0; c < 3; ++c) {
                // The EXR holds the picture decoded to linear (sRGB curve): compare after re-encoding.
                float v = back.pixels()[i][c];
                if (exr) v = v <= 0.0031308f ? v * 12.92f : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
                ASSERT_NEAR(v, grad.pixels()[i][c], exr ? 2e-3f : 1.0f / 255.0f) << name;
            }
    }
    EXPECT_EQ(turbio::readImage(dir / "g.exr").colorSpace, "Linear");

    // Data images: straight alpha survives PNG, TIFF and the premultiplied EXR; a float EXR keeps values
    // outside [0, 1] (motion in pixels).
    RgbaImage rgba(5, 4);
    for (size_t i = 0; i < rgba.size(); ++i) rgba.pixels()[i] = Rgba(0.8f, 0.4f * float(i % 3), 0.1f, float(i) / 19.0f);
    for (const char* name : {"a.png", "a.tif", "a.exr"}) {
        turbio::writeImage(dir / name, rgba);
        turbio::ImageFileInfo info;
        const RgbaImage back = turbio::readImage(dir / name, &info);
        EXPECT_TRUE(info.hasAlpha) << name;
        EXPECT_EQ(info.associatedAlpha, std::string(name) == "a.exr") << name;
        for (size_t i = 1; i < rgba.size(); ++i) // pixel 0 has alpha 0: its colour is not kept by EXR
            ASSERT_NEAR(
                (back.pixels()[i] - rgba.pixels()[i]).length(), 0.0f, std::string(name) == "a.png" ? 4e-3f : 2e-3f)
                << name << " pixel " << i;
    }
    RgbaImage flow(3, 2, Rgba(-12.5f, 3.25f, 0.0f, 1.0f));
    turbio::ImageWriteOptions fo;
    fo.bits = turbio::PixelBits::Float;
    fo.alpha = false;
    turbio::writeImage(dir / "flow.exr", flow, fo);
    EXPECT_EQ(turbio::readImage(dir / "flow.exr").at(2, 1), Rgba(-12.5f, 3.25f, 0.0f, 1.0f));
    turbio::writeImage(dir / "g.jpg", grad);
    EXPECT_EQ(turbio::inspectImage(dir / "g.jpg").channels, 3);

    // Errors name the file; nothing is left behind by a refused write.
    EXPECT_THROW(turbio::readImage(dir / "missing.png"), turb::IoError);
    {
        std::ofstream(dir / "junk.png") << "not a png";
    }
    try {
        turbio::readImage(dir / "junk.png");
        ADD_FAILURE() << "junk accepted";
    } catch (const turb::IoError& e) {
        EXPECT_NE(std::string(e.what()).find("junk.png"), std::string::npos) << e.what();
    }
    EXPECT_THROW(turbio::writeImage(dir / "x.bmpx", grad), turb::ValueError);
    EXPECT_THROW(turbio::writeImage(dir / "h.png", rgba, turbio::ImageWriteOptions{false, turbio::PixelBits::Half}),
        turb::IoError);
    turbio::ImageWriteOptions keep;
    keep.noClobber = true;
    EXPECT_THROW(turbio::writeImage(dir / "g.png", grad, keep), turb::IoError);
    EXPECT_EQ(testutil::countEntries(dir.path()), 9u) << "no temporary files may remain";
}
