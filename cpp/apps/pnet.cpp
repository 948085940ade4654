// pnet: the PlasticityNet command-line program (docs/architecture.md).
//
//   pnet simulate SCENE.json --out DIR [...]   run a scene, write frames (PLY + PNG), stats.csv, checkpoints
//   pnet compare DIR_A DIR_B [...]             per-frame soft and binary IoU of two runs (CSV + plot)
//   pnet video DIR [--out FILE.mp4] [--fps F]  a run's PNG frames as an MP4 (ffmpeg)
//   pnet --version                             the simulator's version (the evaluation keys runs by it)
#include <cstdio>
#include <cstring>

#include "compare_command.hpp"
#include "simulate_command.hpp"
#include "video_command.hpp"

int main(int argc, char** argv) {
    const char* usage =
        "usage: pnet simulate SCENE.json --out DIR [options]   (pnet simulate --help)\n"
        "       pnet compare DIR_A DIR_B [--out DIR] [--dx DX]\n"
        "       pnet video DIR [--out FILE.mp4] [--fps F]\n"
        "       pnet --version\n";
    if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
        std::fputs(usage, argc < 2 ? stderr : stdout);
        return argc < 2 ? 2 : 0;
    }
    if (!std::strcmp(argv[1], "--version")) {
        std::printf("pnet %s\n", PNET_VERSION);
        return 0;
    }
    if (!std::strcmp(argv[1], "simulate")) return pnet::apps::simulate_command(argc - 1, argv + 1);
    if (!std::strcmp(argv[1], "compare")) return pnet::apps::compare_command(argc - 1, argv + 1);
    if (!std::strcmp(argv[1], "video")) return pnet::apps::video_command(argc - 1, argv + 1);
    std::fprintf(stderr, "pnet: unknown command \"%s\"\n%s", argv[1], usage);
    return 2;
}
