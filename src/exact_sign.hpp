// Exact sign of the orientation det[C - O, B - O, d] of doubles, with the floating-point
// expansions of Shewchuk, "Adaptive Precision Floating-Point Arithmetic and Fast Robust
// Geometric Predicates", Discrete & Computational Geometry 18, 1997. Used only when a
// kernel's own evaluation is too close to zero for its sign to be trusted.
#pragma once

#include <cmath>

namespace vrc {
namespace exact {

// Error-free transformations: a op b == x + y exactly (round-to-nearest, no fast-math).
inline void two_sum(double a, double b, double& x, double& y) {
    x = a + b;
    const double bv = x - a, av = x - bv;
    y = (a - av) + (b - bv);
}
inline void two_diff(double a, double b, double& x, double& y) {
    x = a - b;
    const double bv = a - x, av = x + bv;
    y = (a - av) + (bv - b);
}
inline void two_product(double a, double b, double& x, double& y) {
    x = a * b;
    y = std::fma(a, b, -x);
}

/// h = e * b for a nonoverlapping expansion e (increasing magnitude); zeros dropped.
inline int scale_expansion(int n, const double* e, double b, double* h) {
    int k = 0;
    double q, hh, product1, product0, sum;
    two_product(e[0], b, q, hh);
    if (hh != 0) h[k++] = hh;
    for (int i = 1; i < n; ++i) {
        two_product(e[i], b, product1, product0);
        two_sum(q, product0, sum, hh);
        if (hh != 0) h[k++] = hh;
        two_sum(product1, sum, q, hh);  // product1 dominates: a fast two-sum would do
        if (hh != 0) h[k++] = hh;
    }
    if (q != 0 || k == 0) h[k++] = q;
    return k;
}

/// h = e + f (Shewchuk's linear expansion sum, zeros dropped); h holds m + n terms.
inline int expansion_sum(int m, const double* e, int n, const double* f, double* h) {
    int i = 0, j = 0, k = 0;
    auto next = [&]() { return (j >= n || (i < m && std::fabs(e[i]) < std::fabs(f[j]))) ? e[i++] : f[j++]; };
    double q = next(), hh;
    while (i < m || j < n) {
        const double g = next();
        double r;
        two_sum(q, g, r, hh);
        if (hh != 0) h[k++] = hh;
        q = r;
    }
    if (q != 0 || k == 0) h[k++] = q;
    return k;
}

/// Sign (-1, 0, +1) of det[C, B, d] with C = c - o, B = b - o, computed exactly.
inline int orientation(const double* c, const double* b, const double* o, const double* d) {
    double cx[3][2], bx[3][2];  // two-term expansions of the differences, small term first
    for (int k = 0; k < 3; ++k) {
        two_diff(c[k], o[k], cx[k][1], cx[k][0]);
        two_diff(b[k], o[k], bx[k][1], bx[k][0]);
    }
    // det = sum over permutations (i, j, k) of sign * C_i B_j d_k.
    static constexpr int perm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
    double total[128];
    int n_total = 0;
    for (int p = 0; p < 6; ++p) {
        const double dk = p < 3 ? d[perm[p][2]] : -d[perm[p][2]];
        double cd[4], part_lo[8], part_hi[8], term[16], sum[128];
        const int n_cd = scale_expansion(2, cx[perm[p][0]], dk, cd);
        const int n_lo = scale_expansion(n_cd, cd, bx[perm[p][1]][0], part_lo);
        const int n_hi = scale_expansion(n_cd, cd, bx[perm[p][1]][1], part_hi);
        const int n_term = expansion_sum(n_lo, part_lo, n_hi, part_hi, term);
        n_total = n_total ? expansion_sum(n_total, total, n_term, term, sum) : 0;
        const double* src = n_total ? sum : term;
        if (!n_total) n_total = n_term;
        for (int q = 0; q < n_total; ++q) total[q] = src[q];
    }
    const double top = total[n_total - 1];  // the largest-magnitude term decides the sign
    return (top > 0) - (top < 0);
}

}  // namespace exact
}  // namespace vrc
