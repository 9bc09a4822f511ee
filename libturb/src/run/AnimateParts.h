// The parts of runAnimate (private to libturb/src/run): the inputs (AnimateInputs.cc), the pictures of --sheet and
// --dump (AnimatePictures.cc), the measures of --measure (AnimateMeasures.cc); the run is AnimateRun.cc.
#pragma once

#include "RunHelpers.h"

#include <turb/run/Animate.h>

#include <turb/AnimateQuality.h>
#include <turb/ChannelImage.h>
#include <turb/Image.h>
#include <turbio/Strokes.h>

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace turb::run::detail {

/// The example video: an image sequence, a VDB cache through a camera, or the built-in river.
struct Example
{
    std::vector<turb::ChannelImage> frames;
    std::optional<turb::ChannelImage> flow; // a cache's opacity-weighted projected motion
    std::string label;
    std::vector<int> numbers;
};

/// The still and its flow design.
struct Target
{
    turb::ChannelImage rgb;
    std::vector<float> alpha; // output alpha per pixel (the still's own, 1 without one)
    std::optional<turb::ChannelImage> matte;
    std::string colorSpace, label;
    std::optional<turbio::StrokeFile> strokes;
    std::optional<turb::ChannelImage> flow;
    std::optional<turbio::CloneFile> clones; // read once the example's size is known (readClones)
};

/// Applies refine, hm and hmGrid to a.settings and validates them (throws turb::ValueError).
void configure(AnimateJob& a);
/// Reads and checks the example (at least tau + 2 frames, one size).
Example readExample(const AnimateJob& a, int tau);
/// Reads and checks the still, its matte and its flow design.
Target readTarget(const AnimateJob& a);
/// Reads and checks the Clone Brush's strokes (AnimateJob::cloneStrokes) against the example's and the still's sizes.
void readClones(const AnimateJob& a, const Example& example, Target& target);
/// --export-builtin: writes the built-in example and still and says so.
void exportBuiltin(const AnimateJob& a);

/// A picture of the first three channels (clamped to [0, 1]).
turb::Image picture(const turb::ChannelImage& img);
/// A 2D flow as line integral convolution, tinted by speed (black..0.5 * max).
turb::Image flowPicture(const turb::ChannelImage& m);
/// --dump's float EXR of a stage's image.
void writeData(const std::string& path, const turb::ChannelImage& img, bool noClobber);

/// What the contact sheet shows, gathered during the run.
struct SheetParts
{
    std::vector<std::pair<int, turb::Image>> example; // example frame index, picture
    turb::ChannelImage A, v, R0, rough, refined, Aprime;
    std::vector<std::pair<int, turb::Image>> outputs;
};
turb::Image contactSheet(const SheetParts& p, const turb::Image& target, const std::string& title);

/// The quality measures of --measure: the output's flow against the design, its temporal statistics against the
/// example's. They need the example's frames before the library consumes them.
struct Measures
{
    std::optional<turb::TemporalStats> exTemporal, outTemporal;
    std::vector<turb::ChannelImage> outLuma;
    std::optional<turb::FlowAgreement> exampleAgreement, exampleTracks;
};
Measures startMeasures(const AnimateJob& a, const Example& example, const Target& target);
/// The measures into the summary's "quality", and said.
void finishMeasures(const AnimateJob& a, const Measures& m, const turb::ChannelImage& designed, const Target& target,
    nlohmann::json& summary);

} // namespace turb::run::detail
