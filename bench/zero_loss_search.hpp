// The rate search of `pandarcap-bench zero-loss` (RFC 2544 style): which rates to try, given a
// trial (zero_loss_trials.hpp) and what makes one pass.
#pragma once

#include <functional>
#include <nlohmann/json.hpp>

namespace pandarcap::bench {

struct SearchResult {
  double pps = 0;  // the rate actually sent in the best passing trial (0: even the lowest failed)
  bool generator_limited = false;  // that trial could not send its offered rate
};

// Highest rate in [lo, hi] whose trial passes: both ends first, then geometric bisection on the
// offered rate. The result is the achieved rate of the best passing trial: on a 2-core machine
// the generator itself may fall short of the offered rate, and then the result is a lower bound
// (generator_limited). Then, for the plot, rates between tested ones wherever two neighbours are
// more than `max_gap` apart (at most 12 more trials): bisection crowds its trials near the limit,
// and a straight line across a wide gap would draw a curve nobody measured. Every trial is
// appended to `trials`.
SearchResult search(const std::function<nlohmann::ordered_json(double)>& trial,
                    const std::function<bool(const nlohmann::ordered_json&)>& passes, double lo,
                    double hi, int steps, double max_gap, nlohmann::ordered_json& trials);

}  // namespace pandarcap::bench
