#include <turb/Image.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace turb {

namespace {

float clamp01(float v) { return v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v); }

// Piecewise-linear colour maps through control points sampled from the published maps (matplotlib's
// viridis and magma, Moreland's cool-warm) at eight even steps.
Rgb lerpTable(const std::array<Rgb, 8>& t, float x)
{
    x = clamp01(x) * 7.0f;
    const int i = std::min(6, int(x));
    const float f = x - float(i);
    return t[size_t(i)] * (1.0f - f) + t[size_t(i) + 1] * f;
}

const std::array<Rgb, 8> kViridis = {Rgb(0.267f, 0.005f, 0.329f), Rgb(0.275f, 0.194f, 0.497f),
    Rgb(0.213f, 0.359f, 0.552f), Rgb(0.153f, 0.497f, 0.558f), Rgb(0.122f, 0.633f, 0.530f), Rgb(0.288f, 0.758f, 0.428f),
    Rgb(0.626f, 0.854f, 0.223f), Rgb(0.993f, 0.906f, 0.144f)};
const std::array<Rgb, 8> kMagma = {Rgb(0.001f, 0.000f, 0.014f), Rgb(0.107f, 0.066f, 0.270f),
    Rgb(0.316f, 0.071f, 0.485f), Rgb(0.512f, 0.155f, 0.506f), Rgb(0.716f, 0.215f, 0.475f), Rgb(0.907f, 0.331f, 0.378f),
    Rgb(0.991f, 0.611f, 0.416f), Rgb(0.987f, 0.991f, 0.750f)};
const std::array<Rgb, 8> kCoolwarm = {Rgb(0.230f, 0.299f, 0.754f), Rgb(0.392f, 0.513f, 0.914f),
    Rgb(0.580f, 0.700f, 0.990f), Rgb(0.777f, 0.829f, 0.940f), Rgb(0.930f, 0.820f, 0.760f), Rgb(0.968f, 0.659f, 0.537f),
    Rgb(0.901f, 0.447f, 0.348f), Rgb(0.706f, 0.016f, 0.150f)};

} // namespace

Image::Image(int width, int height, const Rgb& fill)
    : mWidth(std::max(0, width)), mHeight(std::max(0, height)), mPixels(size_t(mWidth) * size_t(mHeight), fill)
{}

void Image::blend(int x, int y, const Rgb& c, float alpha)
{
    if (!inside(x, y)) return;
    Rgb& p = at(x, y);
    p = p * (1.0f - alpha) + c * alpha;
}

void Image::fill(const Rgb& c)
{
    std::fill(mPixels.begin(), mPixels.end(), c);
    mTexts.clear();
}

void Image::fillRect(int x0, int y0, int w, int h, const Rgb& c)
{
    for (int y = std::max(0, y0); y < std::min(mHeight, y0 + h); ++y)
        for (int x = std::max(0, x0); x < std::min(mWidth, x0 + w); ++x) at(x, y) = c;
}

void Image::drawRect(int x0, int y0, int w, int h, const Rgb& c)
{
    fillRect(x0, y0, w, 1, c);
    fillRect(x0, y0 + h - 1, w, 1, c);
    fillRect(x0, y0, 1, h, c);
    fillRect(x0 + w - 1, y0, 1, h, c);
}

void Image::drawLine(double x0, double y0, double x1, double y1, const Rgb& c)
{
    // Sample along the line at half-pixel steps and splat with bilinear weights: cheap anti-aliasing.
    const double len = std::hypot(x1 - x0, y1 - y0);
    const int steps = std::max(1, int(std::ceil(len * 2.0)));
    for (int s = 0; s <= steps; ++s) {
        const double t = double(s) / steps;
        const double x = x0 + (x1 - x0) * t, y = y0 + (y1 - y0) * t;
        const int ix = int(std::floor(x)), iy = int(std::floor(y));
        const float fx = float(x - ix), fy = float(y - iy);
        blend(ix, iy, c, (1 - fx) * (1 - fy) * 0.9f + 0.1f);
        blend(ix + 1, iy, c, fx * (1 - fy));
        blend(ix, iy + 1, c, (1 - fx) * fy);
        blend(ix + 1, iy + 1, c, fx * fy);
    }
}

int Image::drawText(int x, int y, const std::string& text, const Rgb& c, int scale)
{
    scale = std::max(1, scale);
    if (!text.empty()) mTexts.push_back(TextLabel{x, y, text, c, scale});
    return textWidth(text, scale);
}

int Image::textWidth(const std::string& text, int scale)
{
    // Monospaced: one advance per code point (UTF-8 continuation bytes do not start a character).
    int n = 0;
    for (unsigned char ch : text)
        if ((ch & 0xC0u) != 0x80u) ++n;
    return n * 6 * std::max(1, scale);
}

void Image::blit(const Image& src, int x, int y)
{
    for (int sy = 0; sy < src.height(); ++sy)
        for (int sx = 0; sx < src.width(); ++sx) set(x + sx, y + sy, src.at(sx, sy));
    for (TextLabel t : src.mTexts) {
        t.x += x;
        t.y += y;
        mTexts.push_back(std::move(t));
    }
}

Image Image::upscaled(int factor) const
{
    factor = std::max(1, factor);
    Image out(mWidth * factor, mHeight * factor);
    for (int y = 0; y < out.height(); ++y)
        for (int x = 0; x < out.width(); ++x) out.at(x, y) = at(x / factor, y / factor);
    for (TextLabel t : mTexts) {
        t.x *= factor;
        t.y *= factor;
        t.scale *= factor;
        out.mTexts.push_back(std::move(t));
    }
    return out;
}

Rgb colormap(Colormap map, float t)
{
    switch (map) {
    case Colormap::Viridis: return lerpTable(kViridis, t);
    case Colormap::Magma: return lerpTable(kMagma, t);
    case Colormap::Coolwarm: return lerpTable(kCoolwarm, t);
    }
    return Rgb(t);
}

namespace {

// Greedy word wrap to at most `width` pixels a line, so a long caption never runs into its neighbour; a
// single word wider than that is cut at the width.
std::vector<std::string> wrapText(const std::string& text, int width, int textScale)
{
    const size_t perLine = size_t(std::max(1, width / (6 * textScale)));
    std::vector<std::string> lines;
    std::string line, word;
    const auto flushWord = [&]() {
        while (word.size() > perLine) {
            if (!line.empty()) {
                lines.push_back(line);
                line.clear();
            }
            lines.push_back(word.substr(0, perLine));
            word.erase(0, perLine);
        }
        if (word.empty()) return;
        if (line.empty()) {
            line = word;
        } else if (line.size() + 1 + word.size() <= perLine) {
            line += ' ' + word;
        } else {
            lines.push_back(line);
            line = word;
        }
        word.clear();
    };
    for (char ch : text) {
        if (ch == ' ') flushWord();
        else word += ch;
    }
    flushWord();
    if (!line.empty()) lines.push_back(line);
    return lines;
}

} // namespace

Image contactSheet(const std::vector<std::vector<SheetCell>>& rows, const std::vector<std::string>& rowLabels,
    const std::string& title, int textScale)
{
    const int pad = 6 * textScale, lineH = Image::textHeight(textScale) + 2 * textScale;
    int cellW = 0, cellH = 0, cols = 0;
    for (const auto& r : rows) {
        cols = std::max(cols, int(r.size()));
        for (const auto& c : r)
            if (c.image) {
                cellW = std::max(cellW, c.image->width());
                cellH = std::max(cellH, c.image->height());
            }
    }
    if (cellW == 0) // no pictures: give captions the widest one's room instead of one character a line
        for (const auto& r : rows)
            for (const auto& c : r) cellW = std::max(cellW, Image::textWidth(c.label, textScale));
    size_t labelLines = 1;
    for (const auto& r : rows)
        for (const auto& c : r) labelLines = std::max(labelLines, wrapText(c.label, cellW, textScale).size());
    const int labelH = int(labelLines) * lineH + pad;
    int rowLabelW = 0;
    for (const auto& l : rowLabels) rowLabelW = std::max(rowLabelW, Image::textWidth(l, textScale) + pad);
    const int width = rowLabelW + cols * (cellW + pad) + pad;
    const std::vector<std::string> titleLines =
        title.empty() ? std::vector<std::string>{} : wrapText(title, width - 2 * pad, textScale);
    const int titleH = titleLines.empty() ? 0 : int(titleLines.size()) * lineH + 2 * pad;
    const int height = titleH + int(rows.size()) * (cellH + labelH + pad) + pad;
    const Rgb bg(0.12f), fg(0.92f);
    Image sheet(width, height, bg);
    for (size_t i = 0; i < titleLines.size(); ++i)
        sheet.drawText(pad, pad + int(i) * lineH, titleLines[i], fg, textScale);
    for (size_t r = 0; r < rows.size(); ++r) {
        const int y = titleH + pad + int(r) * (cellH + labelH + pad);
        if (r < rowLabels.size())
            sheet.drawText(pad / 2, y + cellH / 2 - Image::textHeight(textScale) / 2, rowLabels[r], fg, textScale);
        for (size_t c = 0; c < rows[r].size(); ++c) {
            const int x = rowLabelW + pad + int(c) * (cellW + pad);
            const SheetCell& cell = rows[r][c];
            if (cell.image)
                sheet.blit(*cell.image, x + (cellW - cell.image->width()) / 2, y + (cellH - cell.image->height()) / 2);
            const std::vector<std::string> lines = wrapText(cell.label, cellW, textScale);
            for (size_t i = 0; i < lines.size(); ++i)
                sheet.drawText(x, y + cellH + pad / 2 + int(i) * lineH, lines[i], fg, textScale);
        }
    }
    return sheet;
}

} // namespace turb
