// Which packet decoder runs: the scalar reference or one SIMD instruction set.
//
// One binary carries every SIMD target the compiler could build (Google Highway's runtime
// dispatch); which of them can run is decided on the machine at start-up. "auto" picks the fastest
// the CPU supports, in the order kAutoPreference gives (measured with `pandarcap-bench decode`,
// see docs/performance.md); a named target that the CPU cannot run is an error, never a silent
// fallback to another decoder.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pandarcap {

enum class DecoderTarget {
  kScalar,  // the reference decoder (core/decode/decoder.hpp), always available
  kSse4,    // x86-64 SSE4.2, 4 float lanes
  kAvx2,    // x86-64 AVX2 + FMA, 8 lanes
  kAvx512,  // x86-64 AVX-512 F/BW/DQ/VL, 16 lanes
  kNeon,    // ARMv8 NEON, 4 lanes
  kSve,     // ARM SVE, scalable
  kSve2,    // ARM SVE2, scalable
};

// "scalar", "sse4", "avx2", "avx512", "neon", "sve", "sve2".
std::string_view to_string(DecoderTarget target) noexcept;

// Parses a target name. "auto" is not a target: callers handle it (see choose_decoder_target).
std::optional<DecoderTarget> decoder_target_from_string(std::string_view name) noexcept;

// Targets this binary was built with, scalar first.
std::vector<DecoderTarget> compiled_decoder_targets();

// Targets this binary was built with AND this CPU can run, scalar first.
std::vector<DecoderTarget> supported_decoder_targets();

// The target "auto" resolves to on this machine: the first supported entry of a preference order
// set from `pandarcap-bench decode` measurements (AVX-512, AVX2, SSE4, SVE2, SVE, NEON, scalar;
// see docs/performance.md), where SVE and SVE2 count only with vectors wider than 128 bits
// (instruction counts under QEMU; docs/arm64.md).
DecoderTarget best_decoder_target();

// Resolves a config/CLI value: "auto" or a target name. Returns the target, or an error message
// naming what is supported ("decoder 'avx512': not supported by this CPU (supported: scalar,
// sse4, avx2)").
struct DecoderChoice {
  std::optional<DecoderTarget> target;
  std::string error;
};
DecoderChoice choose_decoder_target(std::string_view name);

// "scalar, sse4, avx2" for messages.
std::string join_targets(const std::vector<DecoderTarget>& targets);

}  // namespace pandarcap
