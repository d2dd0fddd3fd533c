#include "bench/zero_loss_search.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

namespace pandarcap::bench {

using nlohmann::ordered_json;

SearchResult search(const std::function<ordered_json(double)>& trial,
                    const std::function<bool(const ordered_json&)>& passes, double lo, double hi,
                    int steps, double max_gap, ordered_json& trials) {
  SearchResult best;
  std::vector<double> tested;
  auto run = [&](double rate) {
    tested.push_back(rate);
    ordered_json t = trial(rate);
    const bool ok = passes(t);
    t["passed"] = ok;
    const double achieved = t["achieved_pps"].get<double>();
    if (ok && achieved > best.pps) {
      best.pps = achieved;
      best.generator_limited = achieved < 0.97 * rate;
    }
    trials.push_back(t);
    return ok;
  };
  if (run(lo) && hi > lo && !run(hi)) {
    for (int i = 0; i < steps; ++i) {
      const double mid = std::round(std::sqrt(lo * hi));
      if (mid <= lo || mid >= hi) break;
      (run(mid) ? lo : hi) = mid;
    }
  }
  for (int extra = 0; max_gap > 1 && extra < 12; ++extra) {
    std::sort(tested.begin(), tested.end());
    std::optional<double> fill;
    for (std::size_t i = 1; i < tested.size() && !fill; ++i) {
      if (tested[i] > max_gap * tested[i - 1])
        fill = std::round(std::sqrt(tested[i] * tested[i - 1]));
    }
    if (!fill) break;
    run(*fill);
  }
  return best;
}

}  // namespace pandarcap::bench
