// What every scene's assembly shares (its frame, its points in the order the triangles use
// them), and the scene without a hierarchy that a single camera cast needs (its triangles
// are binned to the image's tiles instead, bin_triangles.hpp).
#include <algorithm>
#include <cmath>
#include <vector>

#include "bvh.hpp"

namespace vrc {

void frame_scene(Scene& scene, const double* points, const uint32_t* triangles, std::size_t n_triangles) {
    double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    for (std::size_t i = 0; i < 3 * n_triangles; ++i)
        for (int k = 0; k < 3; ++k) {
            const double x = points[3 * std::size_t(triangles[i]) + k];
            lo[k] = std::min(lo[k], x);
            hi[k] = std::max(hi[k], x);
        }
    double r2 = 0;
    for (int k = 0; k < 3; ++k) {
        scene.anchor[k] = scene.sphere_center[k] = 0.5 * lo[k] + 0.5 * hi[k];
        scene.bounds.lo[k] = relative_down(lo[k], scene.anchor[k]);
        scene.bounds.hi[k] = relative_up(hi[k], scene.anchor[k]);
    }
    for (std::size_t i = 0; i < 3 * n_triangles; ++i) {
        const double* p = points + 3 * std::size_t(triangles[i]);
        double d2 = 0;
        for (int k = 0; k < 3; ++k) d2 += (p[k] - scene.sphere_center[k]) * (p[k] - scene.sphere_center[k]);
        r2 = std::max(r2, d2);
    }
    scene.sphere_radius = std::sqrt(r2);
}

void order_points(Scene& scene, const double* points, std::size_t n_points) {
    constexpr uint32_t kUnused = UINT32_MAX;
    std::vector<uint32_t> index(n_points, kUnused);
    uint32_t n_used = 0;
    for (uint32_t& p : scene.triangles) {
        if (index[p] == kUnused) index[p] = n_used++;
        p = index[p];
    }
    std::vector<double>().swap(scene.points);
    reserve_huge(scene.points, 3 * std::size_t(n_used));
    scene.points.resize(3 * std::size_t(n_used));
    reserve_huge(scene.point_ids, n_used);
    scene.point_ids.resize(n_used);
    for (std::size_t p = 0; p < n_points; ++p)
        if (index[p] != kUnused) {
            for (int k = 0; k < 3; ++k) scene.points[3 * std::size_t(index[p]) + k] = points[3 * p + k];
            scene.point_ids[index[p]] = uint32_t(p);
        }
}

Scene flat_scene(const double* points, std::size_t n_points, const uint32_t* triangles, std::size_t n_triangles) {
    Scene scene;
    scene.triangles.assign(triangles, triangles + 3 * n_triangles);
    order_points(scene, points, n_points);
    scene.prim_ids.resize(n_triangles);
    for (std::size_t i = 0; i < n_triangles; ++i) scene.prim_ids[i] = uint32_t(i);
    if (n_triangles > 0) frame_scene(scene, points, triangles, n_triangles);
    return scene;
}

}  // namespace vrc
