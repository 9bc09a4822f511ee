/// @file Image.h
/// @brief In-memory RGB pictures and the few drawing primitives previews, contact sheets and plots
///        need: rectangles, lines, captions, and perceptual colour maps.
///
/// Pixels hold display-referred values in [0, 1] (already tone-mapped / sRGB-encoded); the IO layer
/// writes them as 8-bit PNG, or as linear half-float EXR (turbio/ImageIO.h). Origin is the top-left
/// corner, x to the right, y down.
///
/// Captions are not rasterised here: libturb holds no fonts and opens no files. drawText() records a
/// TextLabel laid over the pixels, and the IO layer draws the labels with OpenImageIO's render_text in
/// DejaVu Sans Mono at 10 x scale pixels (turbio::writeImage, turbio::withTextDrawn). textWidth() and
/// textHeight() give that font's metrics (advance 6 x scale, cap height 7 x scale), so layouts can be
/// computed without it.
///
/// @code
/// turb::Image img(256, 128, turb::Rgb(0.1f));
/// img.drawText(4, 4, "frame 1001", turb::Rgb(1.0f), 2); // a caption, drawn when written
/// img.set(10, 10, turb::colormap(turb::Colormap::Viridis, 0.5f));
/// @endcode
#pragma once

#include <turb/Field.h>

#include <string>
#include <vector>

namespace turb {

using Rgb = Vec3f;

/// A caption laid over a picture; drawn by the IO layer (see the file comment).
struct TextLabel
{
    int x = 0, y = 0; ///< top-left corner of the first capital letter, in pixels
    std::string text; ///< one line, UTF-8
    Rgb color{1.0f};  ///< display-referred colour
    int scale = 1;    ///< font size 10 x scale pixels (cap height 7 x scale), >= 1
};

class Image
{
public:
    Image() = default;
    Image(int width, int height, const Rgb& fill = Rgb(0.0f));

    int width() const { return mWidth; }
    int height() const { return mHeight; }
    bool empty() const { return mPixels.empty(); }

    bool inside(int x, int y) const { return x >= 0 && y >= 0 && x < mWidth && y < mHeight; }
    const Rgb& at(int x, int y) const { return mPixels[size_t(y) * size_t(mWidth) + size_t(x)]; }
    Rgb& at(int x, int y) { return mPixels[size_t(y) * size_t(mWidth) + size_t(x)]; }
    /// Sets a pixel; silently ignores pixels outside the image (drawing clips).
    void set(int x, int y, const Rgb& c)
    {
        if (inside(x, y)) at(x, y) = c;
    }
    /// Blends `c` over the pixel with opacity `alpha`.
    void blend(int x, int y, const Rgb& c, float alpha);

    /// Fills every pixel and removes every caption.
    void fill(const Rgb& c);
    void fillRect(int x0, int y0, int w, int h, const Rgb& c);
    void drawRect(int x0, int y0, int w, int h, const Rgb& c);
    /// Anti-aliased line of about one pixel width.
    void drawLine(double x0, double y0, double x1, double y1, const Rgb& c);
    /// Adds a caption with its first capital's top-left corner at (x, y); captions lie over the pixels
    /// whatever is drawn later. Returns textWidth(text, scale).
    int drawText(int x, int y, const std::string& text, const Rgb& c, int scale = 1);
    /// Width of a one-line caption in pixels (6 x scale per character, UTF-8 aware).
    static int textWidth(const std::string& text, int scale = 1);
    /// Height of a capital letter in pixels; descenders reach 2.4 x scale below it.
    static int textHeight(int scale = 1) { return 7 * scale; }
    const std::vector<TextLabel>& texts() const { return mTexts; }
    void clearTexts() { mTexts.clear(); }

    /// Copies `src` with its top-left corner at (x, y), clipped; its captions move along.
    void blit(const Image& src, int x, int y);
    /// Nearest-neighbour resize by an integer factor (keeps voxels crisp in previews); captions scale too.
    Image upscaled(int factor) const;

    const std::vector<Rgb>& pixels() const { return mPixels; }
    std::vector<Rgb>& pixels() { return mPixels; }

private:
    int mWidth = 0, mHeight = 0;
    std::vector<Rgb> mPixels;
    std::vector<TextLabel> mTexts;
};

enum class Colormap {
    Viridis, ///< perceptually uniform, dark blue -> yellow (magnitudes)
    Magma,   ///< perceptually uniform, black -> light yellow (vorticity, energy)
    Coolwarm ///< diverging blue -> white -> red (signed values)
};

/// Colour of `t` in [0, 1] (clamped) under the map.
Rgb colormap(Colormap map, float t);

/// Lays images out in a grid with labels under each cell and row labels at the left (contact sheets).
struct SheetCell
{
    const Image* image = nullptr; ///< may be null for an empty cell
    std::string label;
};
Image contactSheet(const std::vector<std::vector<SheetCell>>& rows, const std::vector<std::string>& rowLabels,
    const std::string& title, int textScale = 2);

} // namespace turb
