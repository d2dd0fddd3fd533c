// The median of a benchmark's repeated measurements: the figure the reports quote, since one
// disturbed run on a shared machine moves it less than it moves the mean.
#pragma once

#include <algorithm>
#include <vector>

namespace pandarcap::bench {

// Taken by value: sorting reorders the copy, not the caller's samples. An empty set is 0.
inline double median(std::vector<double> values) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : (values[n / 2 - 1] + values[n / 2]) / 2;
}

}  // namespace pandarcap::bench
