// ThreadSanitizer negative control (built only in the tsan preset, with
// PANDARCAP_RINGBUF_NEGATIVE_CONTROL_RELAXED): the very stress run the test suite uses, on a ring
// whose acquire/release are weakened to relaxed. The consumer then reads slots without a
// happens-before edge to the producer's writes, and TSan must report a data race. CTest passes
// this program only if TSan's report appears in its output; if the stress tests ever stopped
// exercising the ordering, this would fail.
#include <cstdio>
#include <cstring>

#include "support/ringbuf_stress.hpp"

static_assert(pandarcap::ringbuf::detail::kNegativeControl,
              "this program must be built with PANDARCAP_RINGBUF_NEGATIVE_CONTROL_RELAXED");

// argv[1]: "packet-ring" or "typed-queue" (one per process: TSan stops at its first report).
int main(int argc, char** argv) {
  pandarcap::test::StressPlan plan;
  plan.capacity = 64;
  plan.items = 100'000;
  plan.max_producer_batch = 8;
  plan.max_consumer_batch = 8;
  const bool queue = argc > 1 && std::strcmp(argv[1], "typed-queue") == 0;
  const auto outcome =
      queue ? pandarcap::test::stress_typed_queue(plan) : pandarcap::test::stress_packet_ring(plan);
  std::printf("negative control: %llu items received, %llu mismatches\n",
              static_cast<unsigned long long>(outcome.received),
              static_cast<unsigned long long>(outcome.mismatches));
  return 0;
}
