#include "pnet/scene/sampler.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pnet {

namespace {

template <int dim>
bool contains(const SceneObject& object, const Vec<dim>& x) {
    switch (object.shape) {
        case SceneObject::Shape::Box:
            for (int a = 0; a < dim; ++a)
                if (x[a] < object.min[a] || x[a] > object.max[a]) return false;
            return true;
        case SceneObject::Shape::Sphere:
            return (x - object.center).squaredNorm() <= object.radius * object.radius;
        case SceneObject::Shape::Cylinder: {
            // Axis along y through the centre of the bottom face (scene.hpp); only reachable in 3D.
            const double rx = x[0] - object.center[0], rz = x[dim - 1] - object.center[dim - 1];
            return rx * rx + rz * rz <= object.radius * object.radius && x[1] >= object.center[1] &&
                   x[1] <= object.center[1] + object.height;
        }
    }
    return false;
}

}  // namespace

template <int dim>
Particles<dim> sample_particles(const Scene& scene) {
    if (scene.dim != dim)
        throw std::invalid_argument(scene.file + ": sample_particles<" + std::to_string(dim) + ">: the scene is " +
                                    std::to_string(scene.dim) + "D");
    const double h = scene.dx / scene.particles_per_cell;  // lattice spacing, m
    const Vec<dim> origin = scene.domain_min;
    Eigen::Matrix<long, dim, 1> points;  // lattice points per axis
    for (int a = 0; a < dim; ++a) points[a] = static_cast<long>(scene.cells(a)) * scene.particles_per_cell;

    std::vector<Vec<dim>> x;
    std::vector<int> owner;
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        const SceneObject& object = scene.objects[k];
        // Visit the lattice points of the bounding box, one more on each side so that
        // rounding in the index range cannot drop a point: contains() decides.
        const auto [lo, hi] = bounding_box(object);
        Eigen::Matrix<long, dim, 1> first, last;
        for (int a = 0; a < dim; ++a) {
            first[a] = std::max(0L, static_cast<long>(std::ceil((lo[a] - origin[a]) / h - 0.5)) - 1);
            last[a] = std::min(points[a] - 1, static_cast<long>(std::floor((hi[a] - origin[a]) / h - 0.5)) + 1);
        }
        const std::size_t before = x.size();
        if ((last.array() >= first.array()).all()) {
            Eigen::Matrix<long, dim, 1> index = first;
            while (true) {
                Vec<dim> p;
                for (int a = 0; a < dim; ++a) p[a] = origin[a] + (static_cast<double>(index[a]) + 0.5) * h;
                bool taken = !contains<dim>(object, p);
                for (std::size_t j = 0; j < k && !taken; ++j) taken = contains<dim>(scene.objects[j], p);
                if (!taken) {
                    x.push_back(p);
                    owner.push_back(static_cast<int>(k));
                }
                int a = 0;  // odometer increment, x fastest
                for (; a < dim && index[a] == last[a]; ++a) index[a] = first[a];
                if (a == dim) break;
                ++index[a];
            }
        }
        if (x.size() == before) {
            std::ostringstream msg;
            msg << scene.file << ": " << object.json_path << ": no particles: the " << to_string(object.shape)
                << " holds no lattice point (spacing dx / particles_per_cell = " << h
                << " m) that is not already in an earlier object";
            throw SceneError(msg.str());
        }
    }

    Particles<dim> particles;
    particles.resize(x.size());
    const double rest_volume = std::pow(h, dim);  // m^d
    for (std::size_t p = 0; p < x.size(); ++p) {
        const SceneObject& object = scene.objects[owner[p]];
        particles.x[p] = x[p];
        particles.v[p] = object.velocity;
        particles.C[p].setZero();
        particles.F_elastic[p].setIdentity();
        particles.hardening[p] = object.initial_hardening();
        particles.rest_volume[p] = rest_volume;
        particles.mass[p] = object.material.density * rest_volume;  // kg
        particles.object[p] = owner[p];
    }
    return particles;
}

template Particles<2> sample_particles<2>(const Scene&);
template Particles<3> sample_particles<3>(const Scene&);

}  // namespace pnet
