// The geometry buffer a cast writes: every output array, each hit's values assembled by
// the worker that found it, straight into caller-owned arrays (misses in the same pass).
#pragma once

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <utility>
#include <vector>

#include "bvh.hpp"
#include "geometry.hpp"

namespace vrc {

/// Element types of the mesh arrays a cast gathers (VTK's numeric types).
enum class Dtype : uint8_t { i8, u8, i16, u16, i32, u32, i64, u64, f32, f64 };

/// A mesh array gathered at the hits into an output array of the same type: a point array
/// interpolated with the hit's weights (integer arrays, labels and ids, cannot be averaged:
/// they take the value of the point of largest weight, the first on ties), a cell array
/// taking the value of the hit cell. Misses are NaN for floating types, 0 for integers.
struct Field {
    const void* values;   ///< (n_points or n_cells, components), row-major
    void* out;            ///< (rays, components)
    Dtype dtype;
    uint32_t components;
    bool per_point;
    std::size_t row_bytes;  ///< bytes per row of `values`
};

/// What a cast writes, each a caller-owned array with a row per ray, or null when not asked
/// for; and the mesh's data the per-hit values come from (indexed by input triangle).
template <class Real>
struct Outputs {
    int64_t* triangle_id = nullptr;  ///< input triangle index, -1 on a miss
    int64_t* cell_id = nullptr;      ///< input cell index, -1 on a miss
    int64_t* composite_index = nullptr;  ///< flat index of the hit leaf of a composite input, -1 on a miss
    uint8_t* valid = nullptr;        ///< 1 on a hit, 0 on a miss (vtkValidPointMask)
    Real* depth = nullptr;           ///< camera depth (or t for array rays), NaN on a miss
    Real* barycentric = nullptr;     ///< (n, 3) weights of the triangle's points, NaN on a miss
    Real* position = nullptr;        ///< (n, 3) hit point, the weights applied to the points
    Real* normal = nullptr;          ///< (n, 3) unit geometric normal (right-hand rule), NaN on a miss
    std::vector<Field> fields;
    const int64_t* cell_ids = nullptr;           ///< input triangle -> input cell (CellId)
    const int64_t* composite_ids = nullptr;      ///< input triangle -> leaf (CompositeIndex)
    const int64_t* surface_cell_ids = nullptr;   ///< input triangle -> row of the cell arrays
    /// Input triangle i came from cell i (and row i of the cell arrays): cell_ids and
    /// surface_cell_ids are then not read (a scattered load per hit spared).
    bool cells_are_triangles = false;
    /// Only the hits' rows are read (a lidar's returns): a miss is written to depth alone,
    /// which tells them apart, and the other arrays' rows of misses are left as they were.
    /// Most of a scan's beams may miss, and their rows were most of its stores.
    bool returns_only = false;

    /// Whether an output needs the hit's exact depth or weights (else a hit known by its
    /// triangle alone is enough: TileTracer's sure hits).
    [[nodiscard]] bool needs_hit_point() const { return depth || barycentric || position || has_point_fields(); }
    /// Whether the mesh's point arrays are interpolated.
    [[nodiscard]] bool has_point_fields() const {
        return std::any_of(fields.begin(), fields.end(), [](const Field& f) { return f.per_point; });
    }
    /// Bytes written per ray.
    [[nodiscard]] std::size_t bytes_per_ray() const {
        std::size_t bytes = (triangle_id != nullptr) + (cell_id != nullptr) + (composite_index != nullptr);
        bytes = 8 * bytes + (valid != nullptr) + sizeof(Real) * ((depth != nullptr) + 3 * (barycentric != nullptr) +
                                                                 3 * (position != nullptr) + 3 * (normal != nullptr));
        for (const Field& f : fields) bytes += f.row_bytes;
        return bytes;
    }
};

/// Writes hits and misses into the outputs. Called by the workers for disjoint rays.
template <class Real>
class OutputWriter {
    static constexpr Real kNaN = std::numeric_limits<Real>::quiet_NaN();

   public:
    /// `streaming`: rays are stored in the outputs' order, row by row (camera tiles), so the
    /// four- and eight-byte outputs go out with streaming stores (whole lines, no read of
    /// what they replace); each writing thread must then call fence() before the outputs are
    /// read.
    OutputWriter(const Scene& scene, const Outputs<Real>& out, bool streaming = false)
        : scene_(scene), out_(out), streaming_(streaming) {
        for (const Field& f : out.fields)
            if (f.per_point)
                point_fields_.push_back({&f, streaming ? interpolator<true>(f) : interpolator<false>(f)});
            else
                cell_fields_.push_back({&f, streaming ? copier<true>(f) : copier<false>(f)});
    }

    /// Ray k's closest hit (or a miss when none is found); `ray` is read on hits only.
    void operator()(std::size_t k, const Ray& ray, const Hit<Real>& hit) const {
        if (!hit.found()) return misses<1>(k);
        const uint32_t input = by_triangle(k, hit.prim);
        if (out_.depth) put(out_.depth + k, static_cast<Real>(ray.output(hit.t)));
        if (out_.barycentric)
            for (int c = 0; c < 3; ++c) put(out_.barycentric + 3 * k + c, static_cast<Real>(hit.b[c]));
        if (out_.position) {
            const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(hit.prim);
            for (int a = 0; a < 3; ++a) {
                double p = 0;
                for (int c = 0; c < 3; ++c) p += double(hit.b[c]) * scene_.point(tri[c])[a];
                out_.position[3 * k + a] = static_cast<Real>(p);
            }
        }
        if (!point_fields_.empty()) {
            const uint32_t corners[3] = {scene_.input_point(hit.prim, 0), scene_.input_point(hit.prim, 1),
                                         scene_.input_point(hit.prim, 2)};
            for (const auto& [f, interpolate] : point_fields_) interpolate(*f, k, corners, hit.b);
        }
    }

    /// Ray k's hit is triangle `prim` (leaf order), known without its depth or weights
    /// (which are then not asked for: Outputs::needs_hit_point).
    void settled(std::size_t k, uint32_t prim) const { by_triangle(k, prim); }

    /// Asks the cache for what storing a hit on triangle `prim` reads first (its input
    /// triangle index: scattered, mostly a miss).
    void prefetch(uint32_t prim) const { prefetch_line(scene_.prim_ids.data() + prim); }

    /// Asks the cache for the rows of the cell and point arrays the hits on triangles
    /// `prims` read: they lie scattered in the mesh's order, and the copies and
    /// interpolations would each wait on their own.
    void prefetch_rows(const uint32_t* prims, std::size_t n) const {
        if (!cell_fields_.empty())
            for (std::size_t i = 0; i < n; ++i) {
                const std::size_t row = cell_row(scene_.prim_ids[prims[i]]);
                for (const auto& [f, copy] : cell_fields_) prefetch_line(static_cast<const char*>(f->values) + row * f->row_bytes);
            }
        if (point_fields_.empty()) return;
        for (std::size_t i = 0; i < n; ++i)
            for (int c = 0; c < 3; ++c) {
                const std::size_t row = scene_.input_point(prims[i], c);
                for (const auto& [f, interpolate] : point_fields_)
                    prefetch_line(static_cast<const char*>(f->values) + row * f->row_bytes);
            }
    }

    /// Misses for rays k to k + n - 1.
    /// (kCount: n known at compile time, so a single ray's miss is a store per array, not
    /// a fill loop's set-up)
    template <std::size_t kCount = 0>
    void misses(std::size_t k, std::size_t n = kCount) const {
        if constexpr (kCount != 0) n = kCount;
        // (a single ray's miss, most of the rays that pass a small scene by: a store or
        // three per array, where put_n's call and set-up cost a hundred instructions a ray)
        const auto fill = [&](auto* p, std::size_t per_ray, auto v) {
            if constexpr (kCount == 1)
                for (std::size_t i = 0; i < per_ray; ++i) put(p + i, v);
            else
                put_n(p, n * per_ray, v);
        };
        if (out_.returns_only && out_.depth) return fill(out_.depth + k, 1, kNaN);
        if (out_.triangle_id) fill(out_.triangle_id + k, 1, int64_t(-1));
        if (out_.cell_id) fill(out_.cell_id + k, 1, int64_t(-1));
        if (out_.composite_index) fill(out_.composite_index + k, 1, int64_t(-1));
        if (out_.valid) fill(out_.valid + k, 1, uint8_t(0));
        if (out_.depth) fill(out_.depth + k, 1, kNaN);
        if (out_.barycentric) fill(out_.barycentric + 3 * k, 3, kNaN);
        if (out_.position) fill(out_.position + 3 * k, 3, kNaN);
        if (out_.normal) fill(out_.normal + 3 * k, 3, kNaN);
        for (const Field& f : out_.fields)
            with_type(f.dtype, [&](auto zero) {
                using T = decltype(zero);
                const T missing = std::is_floating_point_v<T> ? std::numeric_limits<T>::quiet_NaN() : T(0);
                put_n(static_cast<T*>(f.out) + k * f.components, n * f.components, missing);
            });
    }

    /// Makes this thread's streaming stores visible to others (their reads after it).
    void fence() const {
        if (streaming_) _mm_sfence();
    }

   private:
    /// Stores v at p; with kStream, a value of four or eight bytes by a streaming store (see
    /// the constructor). A tile's row writes each output's lines whole, one after another;
    /// written through the cache, an image's outputs (the default arrays of a 1024 x 1024
    /// cast are 50 to 80 MB, beyond the caches) cost a read of every line first.
    template <bool kStream, class T>
    [[gnu::always_inline]] static void put_as(T* p, T v) {
        if constexpr (kStream && sizeof(T) == 8) {
            long long bits;
            std::memcpy(&bits, &v, sizeof bits);
            _mm_stream_si64(reinterpret_cast<long long*>(p), bits);
        } else if constexpr (kStream && sizeof(T) == 4) {
            int bits;
            std::memcpy(&bits, &v, sizeof bits);
            _mm_stream_si32(reinterpret_cast<int*>(p), bits);
        } else {
            *p = v;
        }
    }
    template <class T>
    [[gnu::always_inline]] void put(T* p, T v) const {
        streaming_ ? put_as<true>(p, v) : put_as<false>(p, v);
    }
    /// Stores v at p .. p + n - 1; streaming, a vector register at a time where aligned (a
    /// run of misses is up to a tile's row: most of an empty frame's stores).
    template <class T>
    void put_n(T* p, std::size_t n, T v) const {
        if (!streaming_ || (sizeof(T) != 4 && sizeof(T) != 8)) return void(std::fill_n(p, n, v));
#if defined(__AVX__)
        using Block = __m256i;
        const auto stream = [](T* at, Block b) { _mm256_stream_si256(reinterpret_cast<Block*>(at), b); };
#else
        using Block = __m128i;
        const auto stream = [](T* at, Block b) { _mm_stream_si128(reinterpret_cast<Block*>(at), b); };
#endif
        constexpr std::size_t kPerBlock = sizeof(Block) / sizeof(T);
        std::size_t i = 0;
        for (; i < n && reinterpret_cast<std::uintptr_t>(p + i) % sizeof(Block) != 0; ++i) put_as<true>(p + i, v);
        T values[kPerBlock];
        std::fill_n(values, kPerBlock, v);
        Block block;
        std::memcpy(&block, values, sizeof block);
        for (; i + kPerBlock <= n; i += kPerBlock) stream(p + i, block);
        for (; i < n; ++i) put_as<true>(p + i, v);
    }

    /// Writes what triangle `prim` alone decides for ray k; returns its input index.
    uint32_t by_triangle(std::size_t k, uint32_t prim) const {
        const uint32_t input = scene_.prim_ids[prim];
        if (out_.triangle_id) put(out_.triangle_id + k, int64_t(input));
        if (out_.cell_id) put(out_.cell_id + k, out_.cells_are_triangles ? int64_t(input) : out_.cell_ids[input]);
        if (out_.composite_index) out_.composite_index[k] = out_.composite_ids[input];
        if (out_.valid) out_.valid[k] = 1;
        if (out_.normal) unit_normal(prim, out_.normal + 3 * k);
        if (!cell_fields_.empty()) {
            const std::size_t row = cell_row(input);
            for (const auto& [f, copy] : cell_fields_) copy(*f, row, k);
        }
        return input;
    }

    /// The row of the cell arrays of input triangle `input`'s cell.
    [[nodiscard]] std::size_t cell_row(uint32_t input) const {
        return out_.cells_are_triangles ? std::size_t(input) : std::size_t(out_.surface_cell_ids[input]);
    }

    /// Calls fn with a zero of the field's element type.
    template <class Fn>
    static void with_type(Dtype dtype, Fn&& fn) {
        switch (dtype) {
            case Dtype::i8: return fn(int8_t(0));
            case Dtype::u8: return fn(uint8_t(0));
            case Dtype::i16: return fn(int16_t(0));
            case Dtype::u16: return fn(uint16_t(0));
            case Dtype::i32: return fn(int32_t(0));
            case Dtype::u32: return fn(uint32_t(0));
            case Dtype::i64: return fn(int64_t(0));
            case Dtype::u64: return fn(uint64_t(0));
            case Dtype::f32: return fn(float(0));
            case Dtype::f64: return fn(double(0));
        }
    }

    /// Copies row `row` of cell field f to ray k's output row.
    using Copy = void (*)(const Field& f, std::size_t row, std::size_t k);

    /// What make(T{}, components) returns for field f's element type T and, for one or three
    /// components, their number as a compile-time constant (else 0: any number): the
    /// function that copies or interpolates f, chosen once per cast, not per hit (a
    /// terrain's two point arrays took longer to interpolate than their scattered rows took
    /// to load).
    template <class Make>
    static auto made_for(const Field& f, Make&& make) {
        using Constant0 = std::integral_constant<uint32_t, 0>;
        decltype(make(int8_t(0), Constant0{})) chosen = nullptr;
        with_type(f.dtype, [&](auto zero) {
            chosen = f.components == 1   ? make(zero, std::integral_constant<uint32_t, 1>{})
                     : f.components == 3 ? make(zero, std::integral_constant<uint32_t, 3>{})
                                         : make(zero, Constant0{});
        });
        return chosen;
    }

    /// The copy of field f's rows (made_for).
    template <bool kStream>
    static Copy copier(const Field& f) {
        return made_for(f, [](auto zero, auto n) -> Copy {
            return &copy_as<kStream, decltype(zero), decltype(n)::value>;
        });
    }

    template <bool kStream, class T, uint32_t kComponents>
    static void copy_as(const Field& f, std::size_t row, std::size_t k) {
        const uint32_t n = kComponents != 0 ? kComponents : f.components;
        const T* from = static_cast<const T*>(f.values) + row * n;
        T* to = static_cast<T*>(f.out) + k * n;
        for (uint32_t j = 0; j < n; ++j) put_as<kStream>(to + j, from[j]);
    }

    /// Writes point field f at ray k's hit on the triangle of input points `corners`, weights b.
    using Interpolate = void (*)(const Field& f, std::size_t k, const uint32_t* corners, const Real b[3]);

    /// The interpolation of field f (made_for).
    template <bool kStream>
    static Interpolate interpolator(const Field& f) {
        return made_for(f, [](auto zero, auto n) -> Interpolate {
            return &interpolate_as<kStream, decltype(zero), decltype(n)::value>;
        });
    }

    /// kComponents: the field's components, or 0 for any number.
    template <bool kStream, class T, uint32_t kComponents>
    static void interpolate_as(const Field& f, std::size_t k, const uint32_t* corners, const Real b[3]) {
        const uint32_t n = kComponents != 0 ? kComponents : f.components;
        const T* values = static_cast<const T*>(f.values);
        T* out = static_cast<T*>(f.out) + k * n;
        if constexpr (std::is_floating_point_v<T>) {
            const T* rows[3] = {values + std::size_t(corners[0]) * n, values + std::size_t(corners[1]) * n,
                                values + std::size_t(corners[2]) * n};
            // the weighted sum in double, in the weights' order (as numpy's reference)
            for (uint32_t j = 0; j < n; ++j) {
                double v = 0;
                for (int c = 0; c < 3; ++c) v += double(b[c]) * double(rows[c][j]);
                put_as<kStream>(out + j, static_cast<T>(v));
            }
        } else {
            const int c = b[1] > b[0] ? (b[2] > b[1] ? 2 : 1) : (b[2] > b[0] ? 2 : 0);
            const T* row = values + std::size_t(corners[c]) * n;
            for (uint32_t j = 0; j < n; ++j) put_as<kStream>(out + j, row[j]);
        }
    }

    /// The unit normal of triangle `prim`: (B - A) x (C - A), normalised.
    void unit_normal(uint32_t prim, Real* out) const {
        const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(prim);
        const double *a = scene_.point(tri[0]), *b = scene_.point(tri[1]), *c = scene_.point(tri[2]);
        const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int k = 0; k < 3; ++k) out[k] = static_cast<Real>(n[k] / length);
    }

    const Scene& scene_;
    const Outputs<Real>& out_;
    bool streaming_;
    std::vector<std::pair<const Field*, Interpolate>> point_fields_;  ///< the point fields, each with its interpolation
    std::vector<std::pair<const Field*, Copy>> cell_fields_;         ///< the cell fields, each with its copy
};

}  // namespace vrc
