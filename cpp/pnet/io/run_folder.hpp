#pragma once
// The output folder of one run of a scene: which files a run owns, so that two runs never mix in
// one folder (docs/architecture.md). A run writes run.json (with its run_id), stats.csv,
// steps.csv, checkpoint.bin and frame_NNNNN.{ply,png,vtu} (a coupled run also
// frame_NNNNN_mesh.{ply,vtu}); `pnet video` adds video.mp4 and
// `pnet compare` a compare_<other>/ folder. Each frame file carries the run_id of the run that
// wrote it (PLY `comment run_id`, PNG tEXt `pnet_run_id`), so readers can refuse a folder whose
// frames come from more than one run.
//
//   fresh run into a folder holding another run: refused (RunFolderError) unless overwrite, which
//     removes that run's files first (and nothing else of the folder);
//   resumed run: keeps its run_id and drops the frames after the checkpoint (they are rewritten);
//   either removes the temporary files a killed writer left (remove_stale_temporaries).
#include <cstddef>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace pnet {

/// A folder that cannot take the run, or whose frames are not all from the run in its run.json:
/// the message names the folder (or file) and what is in it.
class RunFolderError : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

/// The key of a frame PNG's tEXt chunk that holds the run_id.
inline constexpr const char* kPngRunIdKey = "pnet_run_id";

/// A fresh run identifier: 16 hexadecimal digits from std::random_device.
std::string new_run_id();

/// The files and folders in `dir` that belong to a run (above), sorted; empty if `dir` does not exist.
std::vector<std::filesystem::path> run_files(const std::filesystem::path& dir);

/// Throws RunFolderError if `dir` holds a run's files and `overwrite` is false, naming the folder,
/// the run recorded in its run.json (scene, integrator, frames) and how to proceed.
void check_run_folder(const std::filesystem::path& dir, bool overwrite);

/// Removes run_files(dir); returns how many entries were removed.
std::size_t clear_run_folder(const std::filesystem::path& dir);

/// Removes the temporary files a killed run left in `dir`: "<run file>.tmp.<pid>" (write_file_atomically) of a
/// run file or frame file whose writer `pid` no longer runs; returns how many.
std::size_t remove_stale_temporaries(const std::filesystem::path& dir);

/// Removes the frame files of `dir` numbered above `last`; returns how many.
std::size_t remove_frames_after(const std::filesystem::path& dir, int last);

/// The run_id recorded in dir/run.json; "" if the file or the field is missing (runs written
/// before run ids existed).
std::string recorded_run_id(const std::filesystem::path& dir);

/// The frame number of a frame file a run writes: frame_NNNNN.{ply,png,vtu} or
/// frame_NNNNN_mesh.{ply,vtu} (5 to 9 digits); -1 for any other name.
long frame_file_number(const std::filesystem::path& file);

}  // namespace pnet
