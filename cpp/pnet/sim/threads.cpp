#include "pnet/sim/threads.hpp"

#include <sched.h>

#include <cstdlib>
#include <string>

#include <omp.h>

#include "pnet/nn/torchscript.hpp"

namespace pnet {

int available_cores() {
    if (const char* env = std::getenv("OMP_NUM_THREADS")) {
        char* end = nullptr;
        const long n = std::strtol(env, &end, 10);
        if (end != env && *end == '\0' && n > 0) return static_cast<int>(n);
    }
    cpu_set_t set;
    CPU_ZERO(&set);
    if (sched_getaffinity(0, sizeof set, &set) == 0) {
        const int n = CPU_COUNT(&set);
        if (n > 0) return n;
    }
    return omp_get_num_procs();
}

int use_threads(int threads) {
    const int n = threads > 0 ? threads : available_cores();
    TorchAutograd::set_threads(n);  // LibTorch's intra-op count, which it would impose on OpenMP
    omp_set_num_threads(n);
    return n;
}

int thread_count() { return omp_get_max_threads(); }

}  // namespace pnet
