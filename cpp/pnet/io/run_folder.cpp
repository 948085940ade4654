#include "pnet/io/run_folder.hpp"

#include <signal.h>
#include <sys/types.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>

namespace pnet {

namespace fs = std::filesystem;

namespace {

const char* const kRunFiles[] = {"run.json", "stats.csv", "steps.csv", "checkpoint.bin", "video.mp4"};

/// A compare_<name>/ folder holding only what `pnet compare` writes.
bool is_compare_folder(const fs::directory_entry& entry) {
    const std::string name = entry.path().filename().string();
    if (!entry.is_directory() || name.rfind("compare_", 0) != 0) return false;
    for (const fs::directory_entry& inner : fs::directory_iterator(entry.path())) {
        const std::string file = inner.path().filename().string();
        if (file != "iou.csv" && file != "iou.png" && file != "compare.png" &&
            (frame_file_number(inner.path()) < 0 || inner.path().extension() != ".png"))
            return false;
    }
    return true;
}

/// dir/run.json as a JSON object; nullopt if it is missing or not a JSON object.
std::optional<nlohmann::json> read_run_json(const fs::path& dir) {
    std::ifstream in(dir / "run.json");
    if (!in) return std::nullopt;
    try {
        nlohmann::json j = nlohmann::json::parse(in);
        if (j.is_object()) return j;
    } catch (const nlohmann::json::exception&) {
    }
    return std::nullopt;
}

/// "run.json: scene "x", integrator "y", N frames", or that there is no readable run.json.
std::string describe_recorded_run(const fs::path& dir) {
    const std::optional<nlohmann::json> j = read_run_json(dir);
    if (!j) return "no readable run.json";
    auto field = [&](const char* key) { return j->contains(key) ? j->at(key).dump() : std::string("?"); };
    return "run.json: scene " + field("name") + ", integrator " + field("integrator") + ", " + field("frames") +
           " frames";
}

}  // namespace

long frame_file_number(const fs::path& file) {
    const std::string name = file.filename().string();
    const std::string extension = file.extension().string();
    std::string stem = file.stem().string();
    if (extension != ".ply" && extension != ".png" && extension != ".vtu") return -1;
    const std::string mesh = "_mesh";
    if (extension != ".png" && stem.size() > mesh.size() &&
        stem.compare(stem.size() - mesh.size(), mesh.size(), mesh) == 0)
        stem.resize(stem.size() - mesh.size());
    if (stem.rfind("frame_", 0) != 0) return -1;
    const std::string digits = stem.substr(6);
    if (digits.size() < 5 || digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos)
        return -1;
    return std::stol(digits);
}

std::string new_run_id() {
    std::random_device device;
    const unsigned long long value = (static_cast<unsigned long long>(device()) << 32) ^ device();
    char id[17];
    std::snprintf(id, sizeof id, "%016llx", value);
    return id;
}

std::vector<fs::path> run_files(const fs::path& dir) {
    std::vector<fs::path> files;
    if (!fs::is_directory(dir)) return files;
    for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
        const fs::path& p = entry.path();
        const std::string name = p.filename().string();
        const bool owned = (entry.is_regular_file() && (frame_file_number(p) >= 0 || std::find(std::begin(kRunFiles),
                                                                                       std::end(kRunFiles), name) !=
                                                                                 std::end(kRunFiles))) ||
                           is_compare_folder(entry);
        if (owned) files.push_back(p);
    }
    std::sort(files.begin(), files.end());
    return files;
}

void check_run_folder(const fs::path& dir, bool overwrite) {
    if (overwrite) return;
    const std::vector<fs::path> files = run_files(dir);
    if (files.empty()) return;
    throw RunFolderError(dir.string() + ": holds another run (" + describe_recorded_run(dir) + "; " +
                         std::to_string(files.size()) +
                         " files); pass --overwrite to replace it, --resume to continue it, or choose another "
                         "output folder");
}

std::size_t clear_run_folder(const fs::path& dir) {
    const std::vector<fs::path> files = run_files(dir);
    for (const fs::path& p : files) fs::remove_all(p);
    return files.size();
}

std::size_t remove_stale_temporaries(const fs::path& dir) {
    if (!fs::is_directory(dir)) return 0;
    std::vector<fs::path> doomed;
    for (const fs::directory_entry& entry : fs::directory_iterator(dir)) {
        if (!entry.is_regular_file()) continue;
        const std::string name = entry.path().filename().string();
        const std::size_t mark = name.rfind(".tmp.");
        if (mark == std::string::npos) continue;
        const std::string pid = name.substr(mark + 5), target = name.substr(0, mark);
        if (pid.empty() || pid.size() > 9 || pid.find_first_not_of("0123456789") != std::string::npos) continue;
        const bool run_file = frame_file_number(target) >= 0 ||
                              std::find(std::begin(kRunFiles), std::end(kRunFiles), target) != std::end(kRunFiles);
        // A writer that still runs (kill(pid, 0) succeeds, or the process is another user's) keeps its file.
        const bool writer_alive = ::kill(static_cast<pid_t>(std::stol(pid)), 0) == 0 || errno == EPERM;
        if (run_file && !writer_alive) doomed.push_back(entry.path());
    }
    std::size_t removed = 0;
    for (const fs::path& p : doomed) removed += fs::remove(p) ? 1 : 0;
    return removed;
}

std::size_t remove_frames_after(const fs::path& dir, int last) {
    std::size_t removed = 0;
    if (!fs::is_directory(dir)) return 0;
    std::vector<fs::path> doomed;
    for (const fs::directory_entry& entry : fs::directory_iterator(dir))
        if (entry.is_regular_file() && frame_file_number(entry.path()) > last) doomed.push_back(entry.path());
    for (const fs::path& p : doomed) removed += fs::remove(p) ? 1 : 0;
    return removed;
}

std::string recorded_run_id(const fs::path& dir) {
    const std::optional<nlohmann::json> j = read_run_json(dir);
    return j && j->contains("run_id") && j->at("run_id").is_string() ? j->at("run_id").get<std::string>() : "";
}

}  // namespace pnet
