// A scene without a hierarchy: what a single camera cast needs (its triangles are binned
// to the image's tiles instead, bin_triangles.hpp).
#include <algorithm>
#include <cmath>

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

Scene flat_scene(const double* points, std::size_t n_points, const uint32_t* triangles, std::size_t n_triangles) {
    Scene scene;
    scene.points.assign(points, points + 3 * n_points);
    scene.triangles.assign(triangles, triangles + 3 * n_triangles);
    scene.prim_ids.resize(n_triangles);
    for (std::size_t i = 0; i < n_triangles; ++i) scene.prim_ids[i] = uint32_t(i);
    if (n_triangles > 0) frame_scene(scene, points, triangles, n_triangles);
    return scene;
}

}  // namespace vrc
