// runAnimate's pictures (AnimateParts.h): --dump's files and --sheet's contact sheet.
#include "AnimateParts.h"

#include <turb/Render.h>
#include <turbio/ImageIO.h>
#include <turbio/Sequence.h>

#include <algorithm>
#include <cmath>

namespace turb::run::detail {

namespace {

/// A signed image as grey around 0.5 (+-range maps to 0..1), luminance of its channels.
turb::Image signedPicture(const turb::ChannelImage& img, float range)
{
    const turb::ChannelImage y = turb::luminance(img);
    turb::Image p(img.width(), img.height());
    for (int yy = 0; yy < img.height(); ++yy)
        for (int x = 0; x < img.width(); ++x)
            p.at(x, yy) = turb::Rgb(std::clamp(0.5f + 0.5f * y.at(x, yy, 0) / range, 0.0f, 1.0f));
    return p;
}

/// Halves a picture until it is at most `maxWidth` wide (box means), for sheets.
turb::Image fit(const turb::Image& p, int maxWidth)
{
    turb::Image cur = p;
    while (cur.width() > maxWidth) {
        turb::Image h((cur.width() + 1) / 2, (cur.height() + 1) / 2);
        for (int y = 0; y < h.height(); ++y)
            for (int x = 0; x < h.width(); ++x) {
                turb::Rgb s(0.0f);
                int n = 0;
                for (int j = 0; j < 2; ++j)
                    for (int i = 0; i < 2; ++i)
                        if (cur.inside(2 * x + i, 2 * y + j)) {
                            s += cur.at(2 * x + i, 2 * y + j);
                            ++n;
                        }
                h.at(x, y) = s / float(n);
            }
        cur = h;
    }
    return cur;
}

} // namespace

turb::Image picture(const turb::ChannelImage& img)
{
    turb::Image p(img.width(), img.height());
    for (int y = 0; y < img.height(); ++y)
        for (int x = 0; x < img.width(); ++x) {
            const float* v = img.pixel(x, y);
            const int C = img.channels();
            p.at(x, y) = turb::Rgb(std::clamp(v[0], 0.0f, 1.0f), std::clamp(v[std::min(1, C - 1)], 0.0f, 1.0f),
                std::clamp(v[std::min(2, C - 1)], 0.0f, 1.0f));
        }
    return p;
}

turb::Image flowPicture(const turb::ChannelImage& m)
{
    const int W = m.width(), H = m.height();
    turb::VectorField v(
        turb::CoordBBox(turb::Coord(0, 0, 0), turb::Coord(W - 1, H - 1, 0)), turb::Lattice{1.0, {0, 0, 0}});
    float vmax = 1e-6f;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            v(x, H - 1 - y, 0) = turb::Vec3f(m.at(x, y, 0), -m.at(x, y, 1), 0.0f);
            vmax = std::max(vmax, std::hypot(m.at(x, y, 0), m.at(x, y, 1)));
        }
    turb::LicSettings ls;
    ls.view = turb::View::Top;
    ls.width = W;
    turb::Image lic = turb::renderLic(v, ls);
    for (int y = 0; y < lic.height() && y < H; ++y)
        for (int x = 0; x < lic.width() && x < W; ++x) {
            const turb::Rgb c =
                turb::colormap(turb::Colormap::Viridis, std::hypot(m.at(x, y, 0), m.at(x, y, 1)) / vmax);
            const float l = lic.at(x, y)[0];
            lic.at(x, y) =
                turb::Rgb(c[0] * (0.35f + 0.65f * l), c[1] * (0.35f + 0.65f * l), c[2] * (0.35f + 0.65f * l));
        }
    return lic;
}

void writeData(const std::string& path, const turb::ChannelImage& img, bool noClobber)
{
    turb::RgbaImage out(img.width(), img.height());
    const int C = img.channels();
    for (size_t i = 0; i < out.size(); ++i) {
        const float* v = img.pixel(i);
        out.pixels()[i] = turb::Rgba(v[0], C > 1 ? v[1] : v[0], C > 2 ? v[2] : (C > 1 ? 0.0f : v[0]), 1.0f);
    }
    turbio::ImageWriteOptions o;
    o.noClobber = noClobber;
    o.alpha = false;
    o.bits = turbio::PixelBits::Float;
    turbio::ensureParentDirectory(path);
    turbio::writeImage(path, out, o);
}

turb::Image contactSheet(const SheetParts& p, const turb::Image& target, const std::string& title)
{
    const int w = 240;
    std::vector<turb::Image> pics; // owned, referenced by the cells
    pics.reserve(32);
    const auto add = [&](const turb::Image& img) -> const turb::Image* {
        pics.push_back(fit(img, w));
        return &pics.back();
    };
    float rr = 1e-6f;
    for (float v : p.R0.data()) rr = std::max(rr, std::abs(v));
    std::vector<std::vector<turb::SheetCell>> rows(3);
    for (const auto& [i, img] : p.example) rows[0].push_back({add(img), "example frame " + std::to_string(i)});
    rows[0].push_back({add(picture(p.A)), "average A"});
    rows[0].push_back({add(flowPicture(p.v)), "flow v"});
    rows[0].push_back({add(signedPicture(p.R0, 0.5f * rr)), "residual R0"});
    rows[1].push_back({add(target), "target"});
    rows[1].push_back({add(flowPicture(p.rough)), "rough flow"});
    rows[1].push_back({add(flowPicture(p.refined)), "refined flow"});
    rows[1].push_back({add(picture(p.Aprime)), "A'"});
    for (const auto& [i, img] : p.outputs) rows[2].push_back({add(img), "output " + std::to_string(i)});
    return turb::contactSheet(rows, {"example", "design", "output"}, title, 1);
}

} // namespace turb::run::detail
