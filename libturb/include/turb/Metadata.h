/// @file Metadata.h
/// @brief The names of the metadata vdbturb writes into its output files and reads back (Frame::metadata). One
///        list, so a writer and its readers (measure, resume, preview) cannot drift apart.
#pragma once

namespace turb::meta {

// Written by every command.
inline constexpr const char* kCommand = "vdbturb_command"; ///< the command that wrote the file
inline constexpr const char* kDt = "vdbturb_dt";           ///< time per frame of the velocity
/// Seconds per time unit of the written velocity and dt: "1" (world units per second) in the Houdini style.
inline constexpr const char* kTimeUnit = "vdbturb_time_unit";
inline constexpr const char* kDomain = "vdbturb_domain";   ///< "x0 y0 z0 x1 y1 z1": the index box the frame spans
                                                           ///< (a reader holds it whole even where grids are sparse)
/// "x0 y0 z0 x1 y1 z1", the frame's index box: the whole domain of the input the frame was made from (transfer: the
/// target's, refined). Only for framing: preview draws a sequence over it, so output and input columns line up.
inline constexpr const char* kSequenceDomain = "vdbturb_sequence_domain";
inline constexpr const char* kBlenderOffset =
    "vdbturb_blender_offset"; ///< "x y z", world units: what a Blender-style
                              ///< file's transform adds to the frame's lattice (readers take it off)
inline constexpr const char* kInputVelocityUnits = "vdbturb_input_velocity_units"; ///< units the input had

// transfer
inline constexpr const char* kPatchSize = "vdbturb_patch_size";     ///< B, output voxels (measure's block)
inline constexpr const char* kPatchOrigin = "vdbturb_patch_origin"; ///< "x,y,z": an output voxel where a patch starts
inline constexpr const char* kRatio = "vdbturb_ratio";              ///< resolution ratio f
inline constexpr const char* kGlobalPatch = "vdbturb_global_patch"; ///< b, target voxels
inline constexpr const char* kAlpha = "vdbturb_alpha";
inline constexpr const char* kBeta = "vdbturb_beta";
inline constexpr const char* kGamma = "vdbturb_gamma";
inline constexpr const char* kState = "vdbturb_state";       ///< what --resume needs (saveState)
inline constexpr const char* kSettings = "vdbturb_settings"; ///< outputSettingsText(): what --resume compares
/// "style=houdini;half=1;clipping=0;velocity-margin=1": how transfer wrote the frame (--resume keeps it).
inline constexpr const char* kWriteSettings = "vdbturb_write_settings";
/// In a frame written trimmed, in half floats or Blender style: the file name (same directory) of the exact
/// resume state that transfer keeps beside the outputs, a full-precision copy of the last frame written.
inline constexpr const char* kResumeStateFile = "vdbturb_resume_state_file";
/// In a frame whose velocity was written only within N voxels of the smoke: N. Elsewhere its velocity is the
/// up-sampled target's (restore and measure read an unwritten, exactly zero voxel so).
inline constexpr const char* kVelocityMargin = "vdbturb_velocity_margin";
inline constexpr const char* kResumeFrame = "vdbturb_resume_frame"; ///< in that file: the frame it is the state of
inline constexpr const char* kTargetInput = "vdbturb_target";       ///< the target sequence a transfer read
inline constexpr const char* kSourceInput = "vdbturb_source";       ///< the source sequence a transfer read
inline constexpr const char* kSourceFrame = "vdbturb_source_frame"; ///< the source frame the output was made from

// synth
inline constexpr const char* kExemplars = "vdbturb_exemplars";
inline constexpr const char* kOmega = "vdbturb_omega";
inline constexpr const char* kSeed = "vdbturb_seed";

// farm
/// On a frame `farm join` blended from two chunks: "w_a,w_b,d_a,d_b", the detail and density weights.
inline constexpr const char* kFarmBlend = "vdbturb_farm_blend";
/// On a transfer output made with --tile-box: the target box it held, "X0,Y0,Z0,X1,Y1,Z1" (--resume checks it).
inline constexpr const char* kTileBox = "vdbturb_tile_box";
/// On a frame `farm join` assembled from space tiles: "NXxNYxNZ halo H ramp R" (target voxels, output voxels).
inline constexpr const char* kFarmTiles = "vdbturb_farm_tiles";
/// The border planes between the tiles' cores, on the output lattice: "x:64;y:64" (turb::formatTileBorders).
/// `measure` reports tile_block and tile_div_rel next to them.
inline constexpr const char* kTileBorders = "vdbturb_tile_borders";

// sim
inline constexpr const char* kScene = "vdbturb_scene";
inline constexpr const char* kSimResolution = "vdbturb_sim_resolution";
inline constexpr const char* kSimSeed = "vdbturb_sim_seed";
inline constexpr const char* kSimTime = "vdbturb_sim_time";
inline constexpr const char* kUpAxis = "vdbturb_up_axis";

} // namespace turb::meta
