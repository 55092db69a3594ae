// Memory: cache lines asked for ahead of their reads; transparent huge pages for large
// buffers (fresh memory is faulted in a 4 KiB page at a time otherwise, which showed in
// build profiles, and random reads miss the TLB); and the working memory a scene lends its
// camera casts and keeps for the next one (fresh pages would cost a page fault and their
// zeroing on every cast: about 9 % of a frog re-cast in perf samples).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>
#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace vrc {

/// Asks the cache for the line holding `p` (any address: a prefetch never faults). Not
/// __builtin_prefetch: GCC takes that for an instruction without effect and deletes a loop
/// that does nothing else (it may assume such a loop ends, -ffinite-loops), as a loop of
/// prefetches ahead of the real loads is.
[[gnu::always_inline]] inline void prefetch_line(const void* p) {
#if defined(__x86_64__) || defined(__i386__)
    asm volatile("prefetcht0 %0" : : "m"(*static_cast<const char*>(p)));
#else
    __builtin_prefetch(p);
#endif
}

/// Asks the cache for every line of the `bytes` (> 0) from p: a block that is not aligned
/// to lines (a leaf's 104 bytes, eight triangles' 96 bytes of point indices) may span one
/// line more than its size suggests.
[[gnu::always_inline]] inline void prefetch_range(const void* p, std::size_t bytes) {
    const std::uintptr_t first = reinterpret_cast<std::uintptr_t>(p) & ~std::uintptr_t(63);
    const std::uintptr_t last = (reinterpret_cast<std::uintptr_t>(p) + bytes - 1) & ~std::uintptr_t(63);
    for (std::uintptr_t line = first; line <= last; line += 64) prefetch_line(reinterpret_cast<const void*>(line));
}

/// prefetch_range for 1 to 128 bytes without a loop, whose count of lines a branch would
/// follow: they span at most three lines, and when three, the middle byte lies in the
/// middle one. (Two requests may ask for one line.)
[[gnu::always_inline]] inline void prefetch_short(const char* p, std::size_t bytes) {
    prefetch_line(p);
    prefetch_line(p + (bytes - 1) / 2);
    prefetch_line(p + bytes - 1);
}

/// Asks for transparent huge pages over a buffer of 4 MiB or more (its whole 4 KiB pages),
/// before its pages are first touched. Linux only; elsewhere a no-op.
inline void advise_huge(void* data, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (bytes < (std::size_t(4) << 20)) return;
    const auto begin = (reinterpret_cast<std::uintptr_t>(data) + 4095) & ~std::uintptr_t(4095);
    const auto end = (reinterpret_cast<std::uintptr_t>(data) + bytes) & ~std::uintptr_t(4095);
    if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
    (void)data, (void)bytes;
#endif
}

/// Reserves room for n elements, in huge pages where large.
template <class T>
void reserve_huge(std::vector<T>& v, std::size_t n) {
    v.reserve(n);
    advise_huge(v.data(), n * sizeof(T));
}

/// Trims v's capacity to its size (as shrink_to_fit, which takes new memory without
/// advice), in huge pages where large: a scene's arrays are read at random, and with 4 KiB
/// pages most reads of a large scene also missed the TLB.
template <class T>
void shrink_huge(std::vector<T>& v) {
    std::vector<T> fitted;
    reserve_huge(fitted, v.size());
    fitted.assign(v.begin(), v.end());
    v.swap(fitted);
}

/// Blocks of bytes, one per cast running at a time (casts may run concurrently from
/// several Python threads: the GIL is released).
class ScratchPool {
   public:
    struct Block {
        std::unique_ptr<std::byte[]> data;  // aligned like any new[] (at least 16 bytes)
        std::size_t size = 0;
        bool used = false;  // holds what an earlier cast left (a pool serves one scene)
    };

    /// A block of at least `bytes`: a kept one when one is large enough, else a new one.
    [[nodiscard]] Block take(std::size_t bytes) {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            for (auto b = free_.begin(); b != free_.end(); ++b)
                if (b->size >= bytes) {
                    Block block = std::move(*b);
                    free_.erase(b);
                    return block;
                }
        }
        Block block{std::unique_ptr<std::byte[]>(new std::byte[bytes]), bytes};
        advise_huge(block.data.get(), bytes);
        return block;
    }

    /// Keeps `block` for a later cast.
    void give(Block block) {
        std::lock_guard<std::mutex> lock(mutex_);
        free_.push_back(std::move(block));
    }

    /// Bytes kept between casts.
    [[nodiscard]] std::size_t bytes() const {
        std::lock_guard<std::mutex> lock(mutex_);
        std::size_t total = 0;
        for (const Block& b : free_) total += b.size;
        return total;
    }

   private:
    mutable std::mutex mutex_;
    std::vector<Block> free_;
};

}  // namespace vrc
