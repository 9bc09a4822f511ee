// measure --plot's figures (turb/run/Figures.h): gnuplot scripts with their data inline, run by gnuplot.
#include <turb/Error.h>
#include <turb/run/Figures.h>
#include <turbio/ImageIO.h>
#include <turbio/Vdb.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <sstream>

namespace turb::run {

namespace {

const char* const kOutput = "#1a59cc";
const char* const kTarget = "#1a1a1a";
const char* const kSource = "#269940";
const char* const kRule = "#cc3326";

std::string extension(const std::string& path)
{
    std::string e = std::filesystem::path(path).extension().string();
    for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
    return e;
}

// gnuplot's quoted string: backslashes and double quotes escaped.
std::string quoted(const std::string& s)
{
    std::string out = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') out += '\\';
        out += c;
    }
    return out + "\"";
}

// A data block of x y rows; non-finite values are gnuplot's missing value "NaN", which breaks the line there.
std::string dataBlock(const std::string& name, const std::vector<double>& x, const std::vector<double>& y)
{
    std::ostringstream os;
    os.precision(10);
    os << "$" << name << " << EOD\n";
    for (size_t i = 0; i < x.size() && i < y.size(); ++i) {
        os << x[i] << ' ';
        if (std::isfinite(y[i])) os << y[i];
        else os << "NaN";
        os << '\n';
    }
    os << "EOD\n";
    return os.str();
}

// Runs the script into `path`: gnuplot writes PNG/SVG/PDF itself; other formats go through a PNG.
void render(const std::string& path, const std::string& script, int width, int height)
{
    const std::string ext = extension(path);
    const bool direct = ext == ".png" || ext == ".svg" || ext == ".pdf";
    const std::string drawn = direct ? path : path + ".png";
    std::string terminal;
    // noenhanced: metric names and paths hold underscores, which gnuplot's enhanced text would set as subscripts.
    if (ext == ".svg")
        terminal = "svg noenhanced size " + std::to_string(width) + "," + std::to_string(height) + " dynamic";
    else if (ext == ".pdf")
        terminal =
            "pdfcairo noenhanced size " + std::to_string(width / 100.0) + "in," + std::to_string(height / 100.0) + "in";
    else
        terminal = "pngcairo noenhanced size " + std::to_string(width) + "," + std::to_string(height) +
                   " font \"DejaVu Sans,11\"";
    const std::string gp = path + ".gp";
    // Through turb_io as every file of the entry points: a failed write leaves nothing and names the script.
    turbio::writeFileAtomic(gp, "# vdbturb measure --plot: gnuplot " + gp + " redraws " + drawn + "\nset terminal " +
                                    terminal + "\nset output " + quoted(drawn) + "\n" + script);
    const std::string cmd = "gnuplot " + quoted(gp) + " 2>&1";
    std::string said;
    if (std::FILE* p = ::popen(cmd.c_str(), "r")) {
        char buf[256];
        while (std::fgets(buf, sizeof buf, p)) said += buf;
        const int rc = ::pclose(p);
        if (rc != 0 || !std::filesystem::exists(drawn))
            throw turb::IoError(path + ": gnuplot could not draw the figure (" + gp + "): " + said);
    } else {
        throw turb::IoError(path + ": cannot run gnuplot");
    }
    if (direct) return;
    turbio::writeImage(path, turbio::readImage(drawn));
    std::filesystem::remove(drawn);
}

struct Series
{
    std::string label;
    std::vector<double> y;
    const char* color;
    bool dashed = false;
};

// One metric panel of the multiplot: its series over the frames and horizontal reference lines.
std::string panel(const std::string& title, const std::vector<double>& x, const std::vector<Series>& series,
    const std::vector<double>& rules, int index)
{
    std::ostringstream os;
    std::string plots;
    for (size_t k = 0; k < series.size(); ++k) {
        const std::string name = "p" + std::to_string(index) + "_" + std::to_string(k);
        os << dataBlock(name, x, series[k].y);
        plots += std::string(plots.empty() ? "" : ", ") + "$" + name + " using 1:2 with linespoints pt 7 ps 0.6 lw 2 " +
                 (series[k].dashed ? "dt 2 " : "") + "lc rgb \"" + series[k].color + "\" title " +
                 quoted(series[k].label);
    }
    for (double r : rules)
        plots += ", " + std::to_string(r) + " with lines dt 3 lw 1.5 lc rgb \"" + kRule + "\" title \"" + [&] {
            std::ostringstream t;
            t << r;
            return t.str();
        }() + "\"";
    os << "set title " << quoted(title) << "\nset xlabel \"frame\"\nset yrange [0:*]\nplot " << plots << "\n";
    return os.str();
}

std::vector<double> column(
    const std::vector<turb::FrameMeasures>& frames, std::optional<double> turb::FrameMeasures::*member)
{
    std::vector<double> y;
    for (const auto& f : frames) y.push_back((f.*member) ? *(f.*member) : std::numeric_limits<double>::quiet_NaN());
    return y;
}

} // namespace

bool gnuplotAvailable(std::string& why)
{
    if (std::system("gnuplot --version > /dev/null 2>&1") == 0) return true;
    why = "--plot draws its figures with gnuplot, which is not installed (Debian: apt-get install gnuplot-nox)";
    return false;
}

void writeSpectrumFigure(const std::string& path, const turb::FrameMeasures& m, const std::string& title)
{
    std::ostringstream os;
    std::string plots;
    double emax = 0.0, emin = std::numeric_limits<double>::infinity();
    // The dashed source goes last so that it stays visible where it coincides with the output.
    const std::vector<std::tuple<const turb::Spectrum*, const char*, const char*, bool>> parts{
        {&m.spectrumTarget, "target", kTarget, false}, {&m.spectrumOutput, "output", kOutput, false},
        {&m.spectrumSource, "source", kSource, true}};
    for (const auto& [sp, label, color, dashed] : parts) {
        if (sp->empty()) continue;
        os << dataBlock(label, sp->k, sp->energy);
        for (double e : sp->energy)
            if (e > 0.0) emax = std::max(emax, e), emin = std::min(emin, e);
        plots += std::string(plots.empty() ? "" : ", ") + "$" + label +
                 " using 1:($2 > 0 ? $2 : NaN) with lines lw 2 " + (dashed ? "dt 2 " : "") + "lc rgb \"" + color +
                 "\" title \"" + label + "\"";
    }
    os << "set title " << quoted(title) << "\nset xlabel \"k (radians per world unit)\"\nset ylabel \"E(k)\"\n"
       << "set logscale xy\nset grid\nset key top right\n";
    // At most eight decades below the peak: deeper values are round-off and would flatten the rest.
    if (emax > 0.0 && emin < emax * 1e-8) os << "set yrange [" << emax * 1e-8 << ":*]\n";
    if (m.targetNyquist > 0.0)
        os << "set arrow from " << m.targetNyquist << ", graph 0 to " << m.targetNyquist
           << ", graph 1 nohead dt 3 lw 1.5 lc rgb \"" << kRule << "\"\nset label \"target Nyquist\" at "
           << m.targetNyquist << ", graph 0.95 offset 0.5,0 tc rgb \"" << kRule << "\"\n";
    if (plots.empty())
        os << "set label \"no data\" at graph 0.5, graph 0.5 center\nunset logscale\nplot [0:1] [0:1] NaN notitle\n";
    else os << "plot " << plots << "\n";
    render(path, os.str(), 1000, 700);
}

void writeMetricsFigure(
    const std::string& path, const std::vector<turb::FrameMeasures>& frames, const std::string& title)
{
    using FM = turb::FrameMeasures;
    std::vector<double> x;
    for (const auto& f : frames) x.push_back(f.frame);
    bool anyBlock = false;
    for (const auto& f : frames) anyBlock = anyBlock || f.block.has_value();
    std::ostringstream os;
    os << "set multiplot layout 2,3 title " << quoted(title) << " font \",14\"\nset grid\nset key top right\n";
    // Frames are whole numbers: a tick every frame, or every few on long shots.
    if (!x.empty()) os << "set xtics " << std::max(1, int(std::ceil((x.back() - x.front()) / 10.0))) << "\n";
    os << panel("lf_err (good <= 0.05)", x, {{"output", column(frames, &FM::lfErr), kOutput}}, {0.05}, 0);
    os << panel(
        "hf_ratio (good 0.8 - 1.25)", x, {{"output / source", column(frames, &FM::hfRatio), kOutput}}, {0.8, 1.25}, 1);
    os << panel("div_rel (good <= source)", x,
        {{"output", column(frames, &FM::divRel), kOutput},
            {"source", column(frames, &FM::divRelSource), kSource, true}},
        {}, 2);
    os << panel(anyBlock ? "block (good <= 1.05)" : "block: no patch size given", x,
        {{"output", column(frames, &FM::block), kOutput}}, {1.05}, 3);
    os << panel("tcoh (good <= source)", x,
        {{"output", column(frames, &FM::tcoh), kOutput}, {"source", column(frames, &FM::tcohSource), kSource, true}},
        {}, 4);
    os << panel("E_hf (world units^2)", x,
        {{"output", column(frames, &FM::hfEnergy), kOutput},
            {"source", column(frames, &FM::hfEnergySource), kSource, true}},
        {}, 5);
    os << "unset multiplot\n";
    render(path, os.str(), 1920, 860);
}

} // namespace turb::run
