// Two ways of doing a recurring piece of work with the same answers, picked by their
// measured cost: which is cheaper depends on the scene and the rays in ways no count
// predicts (rays that follow one another, one after another or several in flight: it
// depends on whether they find the scene in the caches; a sweep's tiles as bundles or ray
// by ray: bundles took 0.3x to 0.5x on the frog, 1.1x on the terrain's steep rings).
#pragma once

#include <chrono>

namespace vrc {

/// Each way is tried once, then the cheaper one is used, and the other is tried again every
/// `probe` picks so that a change of the work (or of the machine's load) shows. Costs are
/// seconds per unit of work, averaged with the last ones. Only speed depends on the pick.
class CostChooser {
   public:
    /// `first`: the way tried first; `probe`: the other way is tried again every `probe` picks.
    explicit CostChooser(bool first = false, unsigned probe = 16) : first_(first), probe_(probe) {}
    [[nodiscard]] bool pick() {
        if (cost_[first_] < 0) return first_;
        if (cost_[!first_] < 0) return !first_;
        const bool cheaper = cost_[1] < cost_[0];
        return ++picks_ % probe_ == 0 ? !cheaper : cheaper;
    }
    /// The way that leads: the cheaper once both are measured, else the first.
    [[nodiscard]] bool leading() const { return cost_[0] < 0 || cost_[1] < 0 ? first_ : cost_[1] < cost_[0]; }
    void record(bool way, double seconds_per_unit) {
        double& cost = cost_[way ? 1 : 0];
        cost = cost < 0 ? seconds_per_unit : 0.5 * (cost + seconds_per_unit);
    }
    /// Runs work(way) for the way picked, which returns the units of work it did (units
    /// whose cost varies less from one piece of work to the next than the pieces' own),
    /// and records its time over them.
    template <class Work>
    void run(Work&& work) {
        const bool way = pick();
        const auto start = std::chrono::steady_clock::now();
        const double units = work(way);
        if (units > 0) record(way, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / units);
    }

   private:
    bool first_;
    unsigned probe_;
    double cost_[2] = {-1, -1};
    unsigned picks_ = 0;
};

}  // namespace vrc
