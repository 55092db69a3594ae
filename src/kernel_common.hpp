// Small helpers shared by the ray-triangle kernels.
#pragma once

namespace vrc {

/// p - org computed in double, then rounded to Real: every kernel works in coordinates
/// relative to the ray origin (the eye, for camera rays), whatever the world offset.
template <class Real>
inline void relative(const double* p, const double* org, Real out[3]) {
    for (int k = 0; k < 3; ++k) out[k] = static_cast<Real>(p[k] - org[k]);
}

template <class Real>
inline Real dot(const Real a[3], const Real b[3]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

template <class Real>
inline void cross(const Real a[3], const Real b[3], Real out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

template <class Real>
inline void sub(const Real a[3], const Real b[3], Real out[3]) {
    for (int k = 0; k < 3; ++k) out[k] = a[k] - b[k];
}

}  // namespace vrc
