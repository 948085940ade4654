#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "pnet/io/run_folder.hpp"

#include "support/temp_dir.hpp"

namespace pnet {
namespace {

using namespace test;  // TempDir, write_file
namespace fs = std::filesystem;

std::set<std::string> names(const std::vector<fs::path>& paths) {
    std::set<std::string> out;
    for (const fs::path& p : paths) out.insert(p.filename().string());
    return out;
}

TEST(RunFolder, FrameFileNumbers) {
    EXPECT_EQ(frame_file_number("frame_00000.ply"), 0);
    EXPECT_EQ(frame_file_number("out/frame_00042.png"), 42);
    EXPECT_EQ(frame_file_number("frame_123456.vtu"), 123456);
    EXPECT_EQ(frame_file_number("frame_00007_mesh.ply"), 7);
    EXPECT_EQ(frame_file_number("frame_00007_mesh.vtu"), 7);
    EXPECT_EQ(frame_file_number("frame_00007_mesh.png"), -1);  // a run draws one picture per frame
    EXPECT_EQ(frame_file_number("frame_0001.ply"), -1);       // fewer than 5 digits
    EXPECT_EQ(frame_file_number("frame_00001.ply.tmp.123"), -1);  // an interrupted atomic write
    EXPECT_EQ(frame_file_number("frame_00001.csv"), -1);
    EXPECT_EQ(frame_file_number("my_frame_00001.ply"), -1);
    EXPECT_EQ(frame_file_number("frame_0000x.ply"), -1);
}

TEST(RunFolder, RunFilesAreOnlyWhatARunWrites) {
    TempDir dir;
    const fs::path d = dir.file("");
    for (const char* f : {"run.json", "stats.csv", "steps.csv", "checkpoint.bin", "video.mp4", "frame_00000.ply",
                          "frame_00000.png", "frame_00001.vtu", "frame_00001_mesh.ply", "notes.txt",
                          "frame_00002.ply.tmp.77", "my_video.mp4"})
        write_file(dir.file(f), "x");
    fs::create_directories(d / "compare_gt");
    write_file((d / "compare_gt" / "iou.csv").string(), "x");
    write_file((d / "compare_gt" / "frame_00000.png").string(), "x");
    fs::create_directories(d / "compare_mine");  // holds a file pnet compare does not write: the user's
    write_file((d / "compare_mine" / "paper.tex").string(), "x");

    const std::set<std::string> expected = {"run.json",        "stats.csv",       "steps.csv",
                                            "checkpoint.bin",  "video.mp4",       "frame_00000.ply",
                                            "frame_00000.png", "frame_00001.vtu", "frame_00001_mesh.ply",
                                            "compare_gt"};
    EXPECT_EQ(names(run_files(d)), expected);
    EXPECT_TRUE(run_files(d / "missing").empty());

    EXPECT_EQ(clear_run_folder(d), expected.size());
    EXPECT_TRUE(run_files(d).empty());
    for (const char* kept : {"notes.txt", "frame_00002.ply.tmp.77", "my_video.mp4", "compare_mine"})
        EXPECT_TRUE(fs::exists(d / kept)) << kept;
}

TEST(RunFolder, AnotherRunIsRefusedUnlessOverwritten) {
    TempDir dir;
    const fs::path d = dir.file("");
    EXPECT_NO_THROW(check_run_folder(d / "new", false));  // a folder that does not exist yet
    write_file(dir.file("notes.txt"), "mine");
    EXPECT_NO_THROW(check_run_folder(d, false));  // no run in it
    write_file(dir.file("run.json"), R"({"name": "snowball_2d", "integrator": "explicit", "frames": 4})");
    write_file(dir.file("frame_00000.ply"), "x");
    try {
        check_run_folder(d, false);
        ADD_FAILURE() << "a folder holding a run was accepted";
    } catch (const RunFolderError& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind(d.string(), 0), 0u) << what;
        for (const char* needle : {"holds another run", "\"snowball_2d\"", "\"explicit\"", "4 frames", "--overwrite"})
            EXPECT_NE(what.find(needle), std::string::npos) << needle << " not in: " << what;
    }
    EXPECT_NO_THROW(check_run_folder(d, true));
}

TEST(RunFolder, FramesAfterACheckpointAreRemoved) {
    TempDir dir;
    for (const char* f : {"frame_00001.ply", "frame_00002.png", "frame_00003.ply", "frame_00003.png",
                          "frame_00004_mesh.ply", "stats.csv"})
        write_file(dir.file(f), "x");
    EXPECT_EQ(remove_frames_after(dir.file(""), 2), 3u);
    EXPECT_EQ(names(run_files(dir.file(""))),
              (std::set<std::string>{"frame_00001.ply", "frame_00002.png", "stats.csv"}));
}

// A run killed while it wrote a file leaves that file's "<name>.tmp.<pid>" (write_file_atomically); a resumed
// or overwriting run removes those of a run file whose writer is gone, and nothing else.
TEST(RunFolder, AKilledWritersTemporaryFilesAreRemoved) {
    TempDir dir;
    const std::string alive = std::to_string(::getpid());
    for (const char* f : {"stats.csv.tmp.999999999", "frame_00003.ply.tmp.999999998", "checkpoint.bin.tmp.999999997",
                          "notes.txt.tmp.999999999", "stats.csv.tmp.x1", "stats.csv"})
        write_file(dir.file(f), "x");
    write_file(dir.file("steps.csv.tmp." + alive), "x");  // a live writer's (this process)
    EXPECT_EQ(remove_stale_temporaries(dir.file("")), 3u);
    std::set<std::string> left;
    for (const fs::directory_entry& e : fs::directory_iterator(dir.file(""))) left.insert(e.path().filename().string());
    EXPECT_EQ(left, (std::set<std::string>{"notes.txt.tmp.999999999", "stats.csv.tmp.x1", "stats.csv",
                                           "steps.csv.tmp." + alive}));
    EXPECT_EQ(remove_stale_temporaries(dir.file("missing")), 0u);
}

TEST(RunFolder, RunIds) {
    const std::string a = new_run_id(), b = new_run_id();
    EXPECT_EQ(a.size(), 16u);
    EXPECT_EQ(a.find_first_not_of("0123456789abcdef"), std::string::npos);
    EXPECT_NE(a, b);

    TempDir dir;
    EXPECT_EQ(recorded_run_id(dir.file("")), "");  // no run.json
    write_file(dir.file("run.json"), R"({"name": "x"})");
    EXPECT_EQ(recorded_run_id(dir.file("")), "");  // a run from before run ids
    write_file(dir.file("run.json"), R"({"run_id": "00ff00ff00ff00ff"})");
    EXPECT_EQ(recorded_run_id(dir.file("")), "00ff00ff00ff00ff");
}

}  // namespace
}  // namespace pnet
