#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <functional>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "pnet/metrics/iou.hpp"

namespace pnet {
namespace {

constexpr double kDx = 1.0 / 64;  // m; domain [0, 1]^dim

struct ParticleSet {
    std::vector<double> position;  // n dim, particle-major
    std::vector<double> mass;      // kg
};

// A box of (cells x ... x cells) grid cells from corner (in cells), sampled with 2 particles per cell and
// axis at the cell quarter points (the usual MPM lattice), each jittered by up to jitter dx / 4.
template <int dim>
ParticleSet block(const int (&corner)[dim], int cells, double jitter = 0.0, unsigned seed = 1) {
    std::mt19937_64 engine(seed);
    std::uniform_real_distribution<double> noise(-0.25 * jitter * kDx, 0.25 * jitter * kDx);
    ParticleSet set;
    const int per_axis = 2 * cells;
    int count = 1;
    for (int d = 0; d < dim; ++d) count *= per_axis;
    for (int p = 0; p < count; ++p) {
        for (int d = 0, rest = p; d < dim; ++d, rest /= per_axis)
            set.position.push_back((corner[d] + 0.25 + 0.5 * (rest % per_axis)) * kDx + noise(engine));
        set.mass.push_back(1e-3);
    }
    return set;
}

template <int dim>
ParticleSet random_particles(int n, unsigned seed, double lo = 0.1, double hi = 0.9) {
    std::mt19937_64 engine(seed);
    std::uniform_real_distribution<double> x(lo, hi), m(0.5, 2.0);
    ParticleSet set;
    for (int p = 0; p < n; ++p) {
        for (int d = 0; d < dim; ++d) set.position.push_back(x(engine));
        set.mass.push_back(m(engine));
    }
    return set;
}

template <int dim>
GridField rasterize(const ParticleSet& set, std::size_t* clamped = nullptr) {
    const double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {1.0, 1.0, 1.0};
    return rasterize_mass(dim, set.position, set.mass, lo, hi, kDx, clamped);
}

double sum(const std::vector<double>& v) {
    return std::accumulate(v.begin(), v.end(), 0.0);
}

// Expects fn to throw std::invalid_argument whose message contains every one of the given substrings.
void expect_invalid_argument(const std::function<void()>& fn, const std::vector<std::string>& substrings) {
    try {
        fn();
        ADD_FAILURE() << "no exception";
    } catch (const std::invalid_argument& e) {
        for (const std::string& s : substrings)
            EXPECT_NE(std::string(e.what()).find(s), std::string::npos) << "'" << e.what() << "' lacks '" << s << "'";
    }
}

template <typename T>
class IouDim : public ::testing::Test {};
template <int d>
struct Dim {
    static constexpr int value = d;
};
using Dims = ::testing::Types<Dim<2>, Dim<3>>;
TYPED_TEST_SUITE(IouDim, Dims);

TYPED_TEST(IouDim, RasterizedMassSumsToParticleMass) {
    constexpr int dim = TypeParam::value;
    // Interior particles, and a second set with some outside the domain or within dx of its boundary,
    // which are clamped into the grid (counted) without losing mass.
    const ParticleSet inside = random_particles<dim>(5000, 7);
    const ParticleSet mixed = random_particles<dim>(5000, 8, -0.2, 1.2);
    std::size_t expected_clamped = 0;
    for (std::size_t p = 0; p < mixed.mass.size(); ++p) {
        bool out = false;
        for (int d = 0; d < dim; ++d) {
            const double s = mixed.position[p * dim + d] / kDx;
            out = out || s < 1.0 || s > 63.0;
        }
        expected_clamped += out ? 1 : 0;
    }
    ASSERT_GT(expected_clamped, 1000u);

    for (const ParticleSet* set : {&inside, &mixed}) {
        std::size_t clamped = 12345;
        const GridField grid = rasterize<dim>(*set, &clamped);
        EXPECT_EQ(grid.dim, dim);
        for (int d = 0; d < dim; ++d) EXPECT_EQ(grid.nodes[d], 65);
        EXPECT_EQ(grid.value.size(), grid.size());
        EXPECT_EQ(clamped, set == &inside ? 0u : expected_clamped);
        const double total = sum(set->mass);
        EXPECT_NEAR(sum(grid.value), total, 1e-12 * total);  // sum_i w_ip = 1 for every particle
        for (double v : grid.value) EXPECT_GE(v, 0.0);
    }
}

TYPED_TEST(IouDim, IdenticalSets) {
    constexpr int dim = TypeParam::value;
    int corner[dim];
    for (int d = 0; d < dim; ++d) corner[d] = 20 + 3 * d;
    const GridField a = rasterize<dim>(block<dim>(corner, 10, 1.0));
    const GridField b = rasterize<dim>(block<dim>(corner, 10, 1.0));
    const IouResult r = iou(a, b);
    EXPECT_EQ(r.binary, 1.0);
    EXPECT_EQ(r.soft, 1.0);
    // plasticinelab(A, A) = sum a^2 / sum (2a - a^2), below 1 by the block's B-spline rim and the jitter.
    const double max = *std::max_element(a.value.begin(), a.value.end());
    double num = 0.0, den = 0.0;
    for (double v : a.value) {
        num += (v / max) * (v / max);
        den += 2.0 * (v / max) - (v / max) * (v / max);
    }
    EXPECT_NEAR(r.plasticinelab, num / den, 1e-12);
    EXPECT_GT(r.plasticinelab, 0.5);
    EXPECT_LT(r.plasticinelab, 1.0);

    // An indicator field (every node empty or at the maximum) has plasticinelab self-IoU exactly 1.
    GridField indicator = a;
    for (double& v : indicator.value) v = v > 0.5 * max ? 2.5 : 0.0;
    const IouResult s = iou(indicator, indicator);
    EXPECT_EQ(s.plasticinelab, 1.0);
    EXPECT_EQ(s.soft, 1.0);
    EXPECT_EQ(s.binary, 1.0);
}

TYPED_TEST(IouDim, DisjointSetsGiveZero) {
    constexpr int dim = TypeParam::value;
    int left[dim], right[dim];
    for (int d = 0; d < dim; ++d) left[d] = right[d] = 20;
    right[0] = 20 + 8 + 3;  // 3 empty cells between the blocks: no node in both B-spline stencils
    const IouResult r = iou(rasterize<dim>(block<dim>(left, 8)), rasterize<dim>(block<dim>(right, 8)));
    EXPECT_EQ(r.soft, 0.0);
    EXPECT_EQ(r.binary, 0.0);
    EXPECT_EQ(r.plasticinelab, 0.0);
}

TYPED_TEST(IouDim, SoftIouDecreasesWithTranslation) {
    constexpr int dim = TypeParam::value;
    int corner[dim];
    for (int d = 0; d < dim; ++d) corner[d] = 16;
    const GridField reference = rasterize<dim>(block<dim>(corner, 12, 0.5));
    double previous_soft = 2.0, previous_binary = 2.0;
    for (int shift : {0, 1, 2, 4}) {
        corner[0] = 16 + shift;
        const IouResult r = iou(reference, rasterize<dim>(block<dim>(corner, 12, 0.5)));
        EXPECT_LT(r.soft, previous_soft) << "shift " << shift;
        EXPECT_LT(r.binary, previous_binary) << "shift " << shift;
        EXPECT_GT(r.soft, 0.0);
        previous_soft = r.soft;
        previous_binary = r.binary;
    }
}

TYPED_TEST(IouDim, Symmetric) {
    constexpr int dim = TypeParam::value;
    const GridField a = rasterize<dim>(random_particles<dim>(3000, 11, 0.2, 0.6));
    const GridField b = rasterize<dim>(random_particles<dim>(2000, 12, 0.3, 0.8));
    const IouResult ab = iou(a, b), ba = iou(b, a);
    EXPECT_EQ(ab.soft, ba.soft);
    EXPECT_EQ(ab.binary, ba.binary);
    EXPECT_EQ(ab.plasticinelab, ba.plasticinelab);
    EXPECT_GT(ab.soft, 0.0);
    EXPECT_LT(ab.soft, 1.0);
}

#ifdef _OPENMP
TYPED_TEST(IouDim, IndependentOfThreadCount) {
    constexpr int dim = TypeParam::value;
    // Enough particles (several 2^15-particle chunks) and nodes for every parallel loop to run in parallel.
    const ParticleSet set_a = random_particles<dim>(200000, 21);
    const ParticleSet set_b = random_particles<dim>(200000, 22, 0.15, 0.95);
    const int saved = omp_get_max_threads();
    std::vector<GridField> grids;
    std::vector<IouResult> results;
    for (int threads : {1, 2, 3}) {
        omp_set_num_threads(threads);
        grids.push_back(rasterize<dim>(set_a));
        results.push_back(iou(grids.back(), rasterize<dim>(set_b)));
    }
    omp_set_num_threads(saved);
    for (std::size_t t = 1; t < grids.size(); ++t) {
        EXPECT_TRUE(grids[t].value == grids[0].value) << "rasterization differs with " << t + 1 << " threads";
        EXPECT_EQ(results[t].soft, results[0].soft);
        EXPECT_EQ(results[t].binary, results[0].binary);
    }
}
#endif

TEST(Iou, GridLayoutIsXFastest) {
    // One particle on node (10, 20): per axis s is an integer, f = 1, w = (1/8, 3/4, 1/8) on s - 1, s, s + 1.
    const ParticleSet one{{10 * kDx, 20 * kDx}, {2.0}};
    const GridField g = rasterize<2>(one);
    EXPECT_EQ(g.index(10, 20), 10u + 65u * 20u);
    EXPECT_DOUBLE_EQ(g.value[g.index(10, 20)], 2.0 * 0.75 * 0.75);
    EXPECT_DOUBLE_EQ(g.value[g.index(11, 20)], 2.0 * 0.125 * 0.75);
    EXPECT_DOUBLE_EQ(g.value[g.index(9, 21)], 2.0 * 0.125 * 0.125);
    EXPECT_EQ(g.value[g.index(12, 20)], 0.0);

    const ParticleSet one3{{10 * kDx, 20 * kDx, 30 * kDx}, {1.0}};
    const GridField g3 = rasterize<3>(one3);
    EXPECT_EQ(g3.index(1, 2, 3), 1u + 65u * (2u + 65u * 3u));
    EXPECT_DOUBLE_EQ(g3.value[g3.index(10, 21, 29)], 0.75 * 0.125 * 0.125);
}

TEST(Iou, GridCoversTheDomain) {
    // cells = ceil(extent / dx), without an extra cell for an extent that rounds just above a whole number.
    const std::vector<double> position = {0.5, 0.5}, mass = {1.0};
    const double lo[2] = {0.0, 0.0}, hi[2] = {1.1, 0.35};
    const GridField g = rasterize_mass(2, position, mass, lo, hi, 0.1);
    EXPECT_EQ(g.nodes[0], 12);  // 1.1 / 0.1 = 11.000000000000002
    EXPECT_EQ(g.nodes[1], 5);   // ceil(3.5) = 4 cells
    EXPECT_EQ(g.nodes[2], 1);
    EXPECT_NEAR(sum(g.value), 1.0, 1e-15);
}

TEST(Iou, NoParticlesGiveAnEmptyGrid) {
    const GridField empty = rasterize<2>(ParticleSet{});
    EXPECT_EQ(empty.value.size(), 65u * 65u);
    EXPECT_EQ(sum(empty.value), 0.0);
    expect_invalid_argument([&] { iou(empty, empty); }, {"field a is all zero"});
}

TEST(Iou, HandComputedValues) {
    // Two fields on a 4 x 3 grid, non-zero only on the row j = 1:
    //   A = (0, 2, 4, 0.002) -> a = (0, 0.5, 1, 0.0005)   (0.0005 is below the 1e-3 occupancy threshold)
    //   B = (0, 4, 4, 2)     -> b = (0, 1,   1, 0.5)
    //   sum ab = 0.5 + 1 + 0.00025 = 1.50025,  sum (a + b - ab) = 1 + 1 + 0.50025 = 2.50025
    //   sum min(A, B) = 2 + 4 + 0.002 = 6.002,  sum max(A, B) = 4 + 4 + 2 = 10
    //   occupied: A {1, 2}, B {1, 2, 3} -> binary = 2 / 3
    GridField A;
    A.dim = 2;
    A.nodes = {4, 3, 1};
    A.dx = 0.25;
    A.value.assign(12, 0.0);
    GridField B = A;
    const double row_a[4] = {0, 2, 4, 0.002}, row_b[4] = {0, 4, 4, 2};
    for (int i = 0; i < 4; ++i) {
        A.value[A.index(i, 1)] = row_a[i];
        B.value[B.index(i, 1)] = row_b[i];
    }
    const IouResult r = iou(A, B);
    EXPECT_NEAR(r.soft, 0.6002, 1e-15);
    EXPECT_NEAR(r.plasticinelab, 1.50025 / 2.50025, 1e-15);
    EXPECT_DOUBLE_EQ(r.binary, 2.0 / 3.0);
}

TEST(Iou, RejectsFieldsOnDifferentGrids) {
    const GridField a = rasterize<2>(random_particles<2>(100, 1));
    GridField b = a;
    b.nodes = {65, 64, 1};
    b.value.resize(b.size());
    expect_invalid_argument([&] { iou(a, b); }, {"different grids", "65x65", "65x64"});
    b = a;
    b.dx *= 2;
    expect_invalid_argument([&] { iou(a, b); }, {"different grids", "dx"});
    b = a;
    b.origin[1] = 0.5;
    expect_invalid_argument([&] { iou(a, b); }, {"different grids", "origin"});
    const GridField c = rasterize<3>(random_particles<3>(100, 1));
    expect_invalid_argument([&] { iou(a, c); }, {"different grids", "2D", "3D"});
    b = a;
    b.value.pop_back();
    expect_invalid_argument([&] { iou(a, b); }, {"field b is malformed"});
}

TEST(Iou, RejectsAllZeroAndNegativeFields) {
    const GridField a = rasterize<2>(random_particles<2>(100, 1));
    GridField zero = a;
    std::fill(zero.value.begin(), zero.value.end(), 0.0);
    expect_invalid_argument([&] { iou(a, zero); }, {"field b is all zero"});
    expect_invalid_argument([&] { iou(zero, a); }, {"field a is all zero"});
    GridField negative = a;
    negative.value[7] = -1.0;
    expect_invalid_argument([&] { iou(negative, a); }, {"field a", "node 7", "finite and >= 0"});
}

TEST(Iou, RasterizeRejectsBadInput) {
    const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    const std::vector<double> mass = {1.0, 1.0};
    expect_invalid_argument(
        [&] {
            rasterize_mass(2, {0.5, 0.5, 0.5}, mass, lo, hi, kDx);
        },
        {"3 coordinates for 2 masses"});
    expect_invalid_argument([&] { rasterize_mass(4, std::vector<double>(8, 0.5), mass, lo, hi, kDx); }, {"dim is 4"});
    expect_invalid_argument(
        [&] {
            rasterize_mass(2, {0.5, 0.5, NAN, 0.5}, mass, lo, hi, kDx);
        },
        {"particle 1", "finite position"});
    expect_invalid_argument(
        [&] {
            rasterize_mass(2, {0.5, 0.5, 0.5, 0.5}, {1.0, -1.0}, lo, hi, kDx);
        },
        {"particle 1", "mass -1"});
    expect_invalid_argument([&] { rasterize_mass(2, {0.5, 0.5, 0.5, 0.5}, mass, lo, hi, 0.0); }, {"dx"});
    expect_invalid_argument([&] { rasterize_mass(2, {0.5, 0.5, 0.5, 0.5}, mass, hi, lo, kDx); }, {"axis 0"});
    expect_invalid_argument([&] { rasterize_mass(2, {0.5, 0.5, 0.5, 0.5}, mass, lo, hi, 2.0); }, {"need between 2"});
}

}  // namespace
}  // namespace pnet
