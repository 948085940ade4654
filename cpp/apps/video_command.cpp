#include "video_command.hpp"

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "command_line.hpp"
#include "pnet/io/png.hpp"
#include "pnet/io/run_folder.hpp"

extern char** environ;

namespace pnet::apps {

namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage = "usage: pnet video DIR [--out FILE.mp4] [--fps F]\n";

struct Options {
    fs::path dir, out;
    double fps = 0.0;  // 0: from run.json
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg == "--out") {
            o.out = path_value(argc, argv, i);
        } else if (arg == "--fps") {
            o.fps = number_value(argc, argv, i, [](double x) { return std::isfinite(x) && x > 0.0 && x <= 1000.0; },
                                 "a frame rate in (0, 1000] frames per second");
        } else if (!arg.empty() && arg[0] == '-') {
            throw UsageError("unknown option " + arg);
        } else if (o.dir.empty()) {
            o.dir = arg;
        } else {
            throw UsageError("one run folder expected, got a second: " + arg);
        }
    }
    if (o.dir.empty()) throw UsageError("no run folder given");
    return o;
}

/// frame number -> path of DIR/frame_NNNNN.png.
std::map<long, fs::path> frames_in(const fs::path& dir) {
    std::map<long, fs::path> frames;
    for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
        const std::string name = entry.path().filename().string();
        if (name.size() != 15 || name.rfind("frame_", 0) != 0 || name.substr(11) != ".png") continue;
        const std::string digits = name.substr(6, 5);
        if (digits.find_first_not_of("0123456789") != std::string::npos) continue;
        frames[std::stol(digits)] = entry.path();
    }
    return frames;
}

double run_frame_rate(const fs::path& dir) {
    const fs::path run = dir / "run.json";
    if (!fs::exists(run)) return 50.0;
    try {
        std::ifstream in(run);
        const nlohmann::json j = nlohmann::json::parse(in);
        const double frame_dt = j.at("frame_dt").get<double>();
        if (std::isfinite(frame_dt) && frame_dt > 0.0) return 1.0 / frame_dt;
    } catch (const std::exception&) {
    }
    std::fprintf(stderr, "pnet video: %s has no usable frame_dt; using 50 frames per second\n", run.c_str());
    return 50.0;
}

/// Refuses frames that the run recorded in dir/run.json did not write (a folder without a run id,
/// e.g. pictures from elsewhere or a run from before run ids, is taken as it is).
void check_one_run(const fs::path& dir, const std::map<long, fs::path>& frames) {
    const std::string run_id = recorded_run_id(dir);
    if (run_id.empty()) return;
    for (const auto& [number, path] : frames) {
        std::map<std::string, std::string> text;
        try {
            text = read_png_text(path.string());
        } catch (const std::runtime_error& e) {
            throw UsageError(e.what());
        }
        const auto it = text.find(kPngRunIdKey);
        const std::string got = it == text.end() ? "" : it->second;
        if (got != run_id)
            throw UsageError(path.string() + ": not written by the run in " + (dir / "run.json").string() + " (" +
                             (got.empty() ? std::string("no run id") : "run_id " + got) + ", run.json has " + run_id +
                             "); the folder mixes runs: simulate again with --overwrite");
    }
}

/// Runs argv (argv[0] looked up on PATH); returns its exit status, or -1 if it could not start.
int run_process(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    pid_t pid = 0;
    if (const int error = posix_spawnp(&pid, argv[0], nullptr, nullptr, argv.data(), environ); error != 0) {
        errno = error;
        return -1;
    }
    int status = 0;
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

}  // namespace

int video_command(int argc, char** argv) {
    Options o;
    std::map<long, fs::path> frames;
    if (argc == 2 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    try {
        o = parse(argc, argv);
        if (!fs::is_directory(o.dir)) throw UsageError(o.dir.string() + ": not a folder");
        frames = frames_in(o.dir);
        if (frames.empty()) throw UsageError(o.dir.string() + ": no frame_NNNNN.png images (did the run write PNG?)");
        long expected = frames.begin()->first;
        for (const auto& [number, path] : frames) {
            if (number != expected)
                throw UsageError(o.dir.string() + ": frame " + std::to_string(expected) +
                                 ".png is missing (frames must be numbered without gaps)");
            ++expected;
        }
        check_one_run(o.dir, frames);
    } catch (const UsageError& e) {
        std::fprintf(stderr, "pnet video: %s\n%s", e.what(), kUsage);
        return 2;
    } catch (const fs::filesystem_error& e) {
        std::fprintf(stderr, "pnet video: %s\n", e.what());
        return 2;
    }
    if (o.out.empty()) o.out = o.dir / "video.mp4";
    if (o.fps == 0.0) o.fps = run_frame_rate(o.dir);

    const fs::path tmp = o.out.string() + ".tmp.mp4";
    char fps[32];
    std::snprintf(fps, sizeof fps, "%.6g", o.fps);
    // H.264 needs even sizes: pad by one pixel where a frame is odd.
    const std::vector<std::string> command = {
        "ffmpeg", "-loglevel", "error", "-y", "-framerate", fps, "-start_number", std::to_string(frames.begin()->first),
        "-i", (o.dir / "frame_%05d.png").string(), "-frames:v", std::to_string(frames.size()), "-c:v", "libx264",
        "-pix_fmt", "yuv420p", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", tmp.string()};
    const int status = run_process(command);
    if (status != 0) {
        std::error_code ignored;
        fs::remove(tmp, ignored);
        if (status == -1)
            std::fprintf(stderr, "pnet video: cannot run ffmpeg (%s); install it (apt-get install ffmpeg)\n",
                         std::strerror(errno));
        else
            std::fprintf(stderr, "pnet video: ffmpeg failed (exit status %d) encoding %s\n", status, tmp.c_str());
        return 1;
    }
    std::error_code error;
    fs::rename(tmp, o.out, error);
    if (error) {
        std::fprintf(stderr, "pnet video: cannot move the video into place: %s -> %s: %s\n", tmp.c_str(),
                     o.out.c_str(), error.message().c_str());
        fs::remove(tmp, error);
        return 1;
    }
    std::printf("video: %s (%zu frames, %s frames per second)\n", o.out.c_str(), frames.size(), fps);
    return 0;
}

}  // namespace pnet::apps
