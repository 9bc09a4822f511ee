#include <turb/run/Output.h>

#include <turb/run/Reporter.h>
#include <turbio/NanoVdb.h>

#include <algorithm>
#include <sstream>

namespace turb::run {

void warnIfClippedAway(
    const turb::Frame& frame, const turbio::WriteOptions& options, const std::string& path, bool& warned)
{
    if (warned || !(options.densityTolerance > 0.0f) || !frame.hasDensity()) return;
    const auto& v = frame.density.values();
    const float peak = v.empty() ? 0.0f : *std::max_element(v.begin(), v.end());
    if (!(peak > 0.0f) || peak > options.densityTolerance) return;
    warned = true;
    std::ostringstream os;
    os << path << ": --clipping " << options.densityTolerance << " is at or above every density value (peak " << peak
       << "): the density grid is written empty";
    logWarning(os.str());
}

turbio::WriteOptions upResWriteDefaults()
{
    turbio::WriteOptions w;
    w.halfFloat = true;
    w.velocityMargin = kVelocityMarginAuto;
    return w;
}

void checkOutputFormat(const turbio::WriteOptions& w, const std::string& out, const std::string& resumeFlag)
{
    const bool nvdbName = turbio::outputFormatFor(out) == turbio::OutputFormat::NanoVdb;
    if (w.format == turbio::OutputFormat::Vdb && nvdbName)
        throw UsageError("--format vdb but --out '" + out + "' ends in .nvdb: give a .vdb name, or --format nanovdb");
    if (w.format == turbio::OutputFormat::NanoVdb && !nvdbName && out.size() >= 4 &&
        out.compare(out.size() - 4, 4, ".vdb") == 0)
        throw UsageError("--format nanovdb but --out '" + out + "' ends in .vdb: give a .nvdb name");
    const bool nano = turbio::outputFormatFor(out, w.format) == turbio::OutputFormat::NanoVdb;
    if (!nano) {
        if (w.nanoQuantization != turbio::NanoQuantization::Float)
            throw UsageError(std::string("--nanovdb-quant ") + turbio::quantizationName(w.nanoQuantization) +
                             " applies to NanoVDB output; --out '" + out +
                             "' is written as OpenVDB (--half stores 16-bit floats there)");
        return;
    }
    if (w.style == turbio::WriteStyle::Blender)
        throw UsageError("--style blender cannot be written as NanoVDB (Blender's placement and domain live in "
                         "metadata NanoVDB cannot hold; Blender reads OpenVDB): write .vdb, or the default style");
    if (!resumeFlag.empty())
        throw UsageError(resumeFlag +
                         " needs the settings and state a frame records, and NanoVDB files hold no vdbturb metadata: "
                         "write .vdb, and turn the finished frames into NanoVDB with vdbturb convert");
}

} // namespace turb::run
