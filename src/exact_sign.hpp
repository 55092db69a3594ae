// Exact signs of 3x3 determinants of double differences, with the floating-point
// expansions of Shewchuk, "Adaptive Precision Floating-Point Arithmetic and Fast Robust
// Geometric Predicates", Discrete & Computational Geometry 18, 1997. Used only when a
// kernel's own evaluation is too close to zero for its sign to be trusted.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

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

/// A short expansion: the exact value of a double, or of a difference of two doubles.
struct Short {
    double v[2];
    int n;
};

inline Short difference(double a, double b) {
    Short s{};
    two_diff(a, b, s.v[1], s.v[0]);
    s.n = 2;
    if (s.v[0] == 0) s.v[0] = s.v[1], s.n = 1;  // exact in double (nearby points: Sterbenz): half the terms
    return s;
}

/// Whether two columns hold the same values term for term.
inline bool equal(const Short a[3], const Short b[3]) {
    for (int k = 0; k < 3; ++k) {
        if (a[k].n != b[k].n) return false;
        for (int r = 0; r < a[k].n; ++r)
            if (a[k].v[r] != b[k].v[r]) return false;
    }
    return true;
}

/// Whether a column's entries are single doubles (exact differences).
inline bool single(const Short c[3]) { return c[0].n == 1 && c[1].n == 1 && c[2].n == 1; }

/// A column of single doubles as integers times one power of two, when they fit: each
/// entry's significant bits lie within 61 bits of the column's lowest (no subnormals).
/// Scaling a column by a power of two keeps the determinant's sign.
inline bool to_integers(const Short c[3], int64_t out[3]) {
    int lowest = INT32_MAX, highest = INT32_MIN, low[3] = {0, 0, 0};
    uint64_t mantissa[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) {
        uint64_t bits;
        std::memcpy(&bits, &c[k].v[0], sizeof bits);
        const int exponent = int(bits >> 52 & 0x7ff);
        if (exponent == 0) {
            if ((bits << 1) != 0) return false;  // subnormal
            continue;                            // zero
        }
        const uint64_t m = (bits & ((uint64_t(1) << 52) - 1)) | (uint64_t(1) << 52);
        const int zeros = __builtin_ctzll(m);
        mantissa[k] = m >> zeros;
        low[k] = exponent - 1075 + zeros;  // value = mantissa 2^low
        lowest = std::min(lowest, low[k]);
        highest = std::max(highest, exponent - 1023);  // value < 2^(highest + 1)
    }
    if (lowest == INT32_MAX) return (out[0] = out[1] = out[2] = 0), true;
    if (highest - lowest + 1 > 61) return false;
    for (int k = 0; k < 3; ++k) {
        const int64_t v = mantissa[k] == 0 ? 0 : int64_t(mantissa[k] << (low[k] - lowest));
        out[k] = c[k].v[0] < 0 ? -v : v;
    }
    return true;
}

/// The exact sign of a determinant of columns of integers below 2^61: each cofactor
/// a_i b_j - a_j b_i fits 128 bits, and sum over k of c_k X_k is split as
/// (sum c_k hi(X_k)) 2^64 + sum c_k lo(X_k), both sums within 128 bits.
inline int det3_sign(const int64_t a[3], const int64_t b[3], const int64_t c[3]) {
    __int128 high = 0, low = 0;
    for (int k = 0; k < 3; ++k) {
        const int i = (k + 1) % 3, j = (k + 2) % 3;
        const __int128 cofactor = __int128(a[i]) * b[j] - __int128(a[j]) * b[i];
        const int64_t cofactor_high = int64_t(cofactor >> 64);                 // floor
        const uint64_t cofactor_low = uint64_t(cofactor & ~uint64_t(0));       // cofactor - high 2^64
        high += __int128(c[k]) * cofactor_high;
        low += __int128(c[k]) * __int128(cofactor_low);
    }
    high += low >> 64;  // floor: low = (low >> 64) 2^64 + its last 64 bits, in [0, 2^64)
    if (high != 0) return high > 0 ? 1 : -1;
    return uint64_t(low & ~uint64_t(0)) != 0 ? 1 : 0;
}

/// The exact sign of a determinant of single doubles whose columns span too many bits for
/// integers: its six products are 24 doubles exactly (a b = x + y, then x c and y c),
/// summed exactly into a nonoverlapping expansion by Shewchuk's Grow-Expansion with zeros
/// dropped (an exact zero keeps it short); its largest term has the sum's sign.
inline int singles_det3_sign(const Short c0[3], const Short c1[3], const Short c2[3]) {
    static constexpr int perm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
    double e[24];
    int m = 0;
    const auto grow = [&](double q) {
        int k = 0;
        for (int i = 0; i < m; ++i) {
            double sum, h;
            two_sum(q, e[i], sum, h);
            q = sum;
            if (h != 0) e[k++] = h;
        }
        if (q != 0) e[k++] = q;
        m = k;
    };
    for (int p = 0; p < 6; ++p) {
        const double a = c0[perm[p][0]].v[0], b = c1[perm[p][1]].v[0];
        const double c = p < 3 ? c2[perm[p][2]].v[0] : -c2[perm[p][2]].v[0];
        double x, y, x1, x0, y1, y0;
        two_product(a, b, x, y);
        two_product(x, c, x1, x0);
        two_product(y, c, y1, y0);
        grow(y0), grow(x0), grow(y1), grow(x1);
    }
    return m == 0 ? 0 : (e[m - 1] > 0) - (e[m - 1] < 0);
}

/// A double-double value hi + lo, |lo| <= ulp(hi) / 2 (as two_sum and two_product leave it).
struct Twofold {
    double hi, lo;
};
inline Twofold twofold(const Short& s) { return s.n == 2 ? Twofold{s.v[1], s.v[0]} : Twofold{s.v[0], 0.0}; }
/// Sum, relative error below 3u^2 / (1 - 4u) (u = 2^-53; Joldes, Muller and Popescu,
/// "Tight and rigorous error bounds for basic building blocks of double-word arithmetic",
/// ACM TOMS 44, 2017: AccurateDWPlusDW).
inline Twofold add(Twofold x, Twofold y) {
    double sh, sl, th, tl, vh, vl, zh, zl;
    two_sum(x.hi, y.hi, sh, sl);
    two_sum(x.lo, y.lo, th, tl);
    two_sum(sh, sl + th, vh, vl);
    two_sum(vh, tl + vl, zh, zl);
    return {zh, zl};
}
/// Product with an FMA, relative error below 5u^2 (ibid., DWTimesDW3, bounded 4u^2 there).
inline Twofold mul(Twofold x, Twofold y) {
    double ch, cl;
    two_product(x.hi, y.hi, ch, cl);
    const double t = std::fma(x.lo, y.hi, std::fma(x.hi, y.lo, x.lo * y.lo));
    double zh, zl;
    two_sum(ch, cl + t, zh, zl);
    return {zh, zl};
}

/// The sign of the 3x3 determinant whose columns are c0, c1, c2 (exact as double-doubles)
/// from double-double arithmetic: det = sum over k of c2[k] (c0[i] c1[j] - c0[j] c1[i]).
/// Each cofactor carries at most 5u^2 + 3u^2 of its permanent |c0[i] c1[j]| +
/// |c0[j] c1[i]|, its product with c2[k] 5u^2 more, and the two sums 3u^2 each of the
/// whole permanent P: below 17u^2 P with the second-order terms, so 32u^2 P (P from the
/// heads, whose own roundings are far smaller) leaves a wide margin. 0 when |det| is
/// within that (then the expansions decide), or when P leaves the range where products
/// and their errors are normal doubles.
inline int twofold_det3_sign(const Twofold c0[3], const Twofold c1[3], const Twofold c2[3]) {
    Twofold det{0.0, 0.0};
    double permanent = 0;
    for (int k = 0; k < 3; ++k) {
        const int i = (k + 1) % 3, j = (k + 2) % 3;
        const Twofold a = mul(c0[i], c1[j]), b = mul(c0[j], c1[i]);
        const Twofold cofactor = add(a, Twofold{-b.hi, -b.lo});
        det = add(det, mul(c2[k], cofactor));
        permanent += std::fabs(c2[k].hi) * (std::fabs(c0[i].hi * c1[j].hi) + std::fabs(c0[j].hi * c1[i].hi));
    }
    constexpr double kBound = 32 * 0x1p-106;
    if (!(permanent > 0x1p-800 && permanent < 0x1p800)) return 0;
    const double value = det.hi + det.lo;
    if (std::fabs(value) > kBound * permanent * 1.01) return (value > 0) - (value < 0);
    return 0;
}

/// Exact sign of the 3x3 determinant whose columns are given as short expansions: from
/// double-double arithmetic when that tells it (nearly always: a kernel asks only when its
/// own double-precision value is within its rounding of zero), else from expansions.
inline int det3_sign(const Short c0[3], const Short c1[3], const Short c2[3]) {
    // two equal columns: a ray aimed exactly at a point (its direction the point less the
    // origin, exactly) meets the edges through that point so
    if (equal(c0, c1) || equal(c1, c2) || equal(c0, c2)) return 0;
    const Twofold t0[3] = {twofold(c0[0]), twofold(c0[1]), twofold(c0[2])};
    const Twofold t1[3] = {twofold(c1[0]), twofold(c1[1]), twofold(c1[2])};
    const Twofold t2[3] = {twofold(c2[0]), twofold(c2[1]), twofold(c2[2])};
    if (const int sign = twofold_det3_sign(t0, t1, t2)) return sign;
    if (single(c0) && single(c1) && single(c2)) {
        int64_t i0[3], i1[3], i2[3];
        if (to_integers(c0, i0) && to_integers(c1, i1) && to_integers(c2, i2)) return det3_sign(i0, i1, i2);
        return singles_det3_sign(c0, c1, c2);
    }
    static constexpr int perm[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
    double total[256], sum[256];
    int n_total = 0;
    for (int p = 0; p < 6; ++p) {
        // term = c0[i] * c1[j] * c2[k], negated for odd permutations
        double ab[8], term[16], part[8];
        int n_ab = 0, n_term = 0;
        const Short& a = c0[perm[p][0]];
        const Short& b = c1[perm[p][1]];
        const Short& c = c2[perm[p][2]];
        for (int q = 0; q < b.n; ++q) {
            const int n_part = scale_expansion(a.n, a.v, b.v[q], part);
            n_ab = n_ab ? expansion_sum(n_ab, ab, n_part, part, sum) : 0;
            const double* src = n_ab ? sum : part;
            if (!n_ab) n_ab = n_part;
            for (int r = 0; r < n_ab; ++r) ab[r] = src[r];
        }
        for (int q = 0; q < c.n; ++q) {
            const double factor = p < 3 ? c.v[q] : -c.v[q];
            double scaled[16];
            const int n_scaled = scale_expansion(n_ab, ab, factor, scaled);
            n_term = n_term ? expansion_sum(n_term, term, n_scaled, scaled, sum) : 0;
            const double* src = n_term ? sum : scaled;
            if (!n_term) n_term = n_scaled;
            for (int r = 0; r < n_term; ++r) term[r] = src[r];
        }
        n_total = n_total ? expansion_sum(n_total, total, n_term, term, sum) : 0;
        const double* src = n_total ? sum : term;
        if (!n_total) n_total = n_term;
        for (int r = 0; r < n_total; ++r) total[r] = src[r];
    }
    const double top = total[n_total - 1];  // the largest-magnitude term decides the sign
    return (top > 0) - (top < 0);
}

/// Whether points p and q are the same point.
inline bool same(const double* p, const double* q) { return p[0] == q[0] && p[1] == q[1] && p[2] == q[2]; }

/// Sign (-1, 0, +1) of det[C, B, d] with C = c - o, B = b - o: the side of the plane
/// through the ray and an edge, computed exactly. A ray leaving a vertex meets the two
/// edges through it so, in a zero column: no expansions for that.
inline int orientation(const double* c, const double* b, const double* o, const double* d) {
    if (same(c, o) || same(b, o)) return 0;
    Short cc[3], bb[3], dd[3];
    for (int k = 0; k < 3; ++k) {
        cc[k] = difference(c[k], o[k]);
        bb[k] = difference(b[k], o[k]);
        dd[k] = Short{{d[k], 0.0}, 1};
    }
    return det3_sign(cc, bb, dd);
}

/// Sign of det[A, B, C] with A = a - o, ...: the side of the triangle's plane the point o
/// lies on (Shewchuk's orient3d), computed exactly.
inline int volume(const double* a, const double* b, const double* c, const double* o) {
    if (same(a, o) || same(b, o) || same(c, o)) return 0;
    Short aa[3], bb[3], cc[3];
    for (int k = 0; k < 3; ++k) {
        aa[k] = difference(a[k], o[k]);
        bb[k] = difference(b[k], o[k]);
        cc[k] = difference(c[k], o[k]);
    }
    return det3_sign(aa, bb, cc);
}

}  // namespace exact
}  // namespace vrc
