// measure's second tier as a settings table (turb/run/Settings.h): the region and lattice a metric uses when the
// metadata does not say, what to skip, and the plots' format, in the order --help-all lists them.
#include "SettingsRows.h"

#include <turb/run/Flags.h>
#include <turb/run/Measure.h>

namespace turb::run {

namespace {

using detail::add;
using Table = SettingsTable<MeasureJob>;

// 0 takes the output's metadata; a seam every voxel (1) is no patch grid.
std::string patchSizeProblem(const std::string& text)
{
    double v = 0.0;
    return parseNumber(text, v) && v > 0.0 && v < 2.0
               ? "must be 0 (the output's vdbturb_patch_size metadata) or from 2 to 4096"
               : "";
}

} // namespace

const SettingsTable<MeasureJob>& measureSettings()
{
    static const Table table = [] {
        Table t;
        add(t, "patchSize", "patch-size",
            "Seam spacing for block, in output voxels (0: the output's vdbturb_patch_size metadata)",
            TURB_FIELD(settings.patchSize), 0, 4096)
            .validate = patchSizeProblem;
        add(t, "patchOrigin", "patch-origin",
            "An output voxel where a patch starts, X,Y,Z (default: vdbturb_patch_origin metadata, else 0,0,0)",
            TURB_FIELD(patchOrigin));
        add(t, "tile-borders", "",
            "Space-tile border planes for tile_block and tile_div_rel, in output voxels, e.g. x:64;y:64 (default: the "
            "output's vdbturb_tile_borders metadata, which farm join writes)",
            TURB_FIELD(tileBorders));
        add(t, "tile-border-width", "",
            "Output voxels either side of a tile border that tile_* cover (0: 2 patch sizes)",
            TURB_FIELD(settings.tileBorderWidth), 0, 4096);
        add(t, "alignment", "align",
            "Output against the refined target lattice: auto, world (the transforms) or index (the voxels)",
            TURB_FIELD(settings.alignment))
            .choices = {
            {"auto", int(Alignment::Auto)}, {"world", int(Alignment::World)}, {"index", int(Alignment::Index)}};
        add(t, "sourceRead.extendVelocity", "source-extend-velocity",
            "Continue the source's velocity this many voxels past its active region, as transfer reads it (0: as "
            "written)",
            TURB_FIELD(sourceExtend), 0, 64);
        // MeasureJob::spectra under another key: --spectra is the everyday flag for the JSON arrays.
        add(t, "computeSpectra", "", "Energy spectra (false: skip the FFTs unless --plot or --spectra needs them)",
            TURB_FIELD(spectra));
        add(t, "structure", "",
            "The structure numbers aniso, isotropy, lattice, detail_scale and vort_peak (false: skip them)",
            TURB_FIELD(settings.structure));
        add(t, "plot-format", "", "Picture format of --plot (exr and tif from gnuplot's PNG)", TURB_FIELD(plotFormat))
            .oneOf = {"png", "svg", "pdf", "exr", "tif"};
        return t;
    }();
    return table;
}

const std::vector<OldSpelling>& measureOldSpellings()
{
    static const std::vector<OldSpelling> spellings{
        {"no-spectra", "computeSpectra", "false", ""}, {"no-structure", "structure", "false", ""}};
    return spellings;
}

} // namespace turb::run
