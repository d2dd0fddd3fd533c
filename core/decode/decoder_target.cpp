#include "core/decode/decoder_target.hpp"

#if defined(__aarch64__)
#include <sys/prctl.h>
#endif

#include <algorithm>
#include <array>

namespace pandarcap {

namespace {

constexpr std::array<std::pair<DecoderTarget, std::string_view>, 7> kNames = {{
    {DecoderTarget::kScalar, "scalar"},
    {DecoderTarget::kSse4, "sse4"},
    {DecoderTarget::kAvx2, "avx2"},
    {DecoderTarget::kAvx512, "avx512"},
    {DecoderTarget::kNeon, "neon"},
    {DecoderTarget::kSve, "sve"},
    {DecoderTarget::kSve2, "sve2"},
}};

// What "auto" prefers, best first. AVX-512 leaves 8 of its 48 lanes idle on a 40-channel block,
// yet `pandarcap-bench decode` measured it 12-18 % faster than AVX2 on this workload
// (docs/performance.md), so it goes first.
constexpr std::array kAutoPreference = {
    DecoderTarget::kAvx512, DecoderTarget::kAvx2, DecoderTarget::kSse4,  DecoderTarget::kSve2,
    DecoderTarget::kSve,    DecoderTarget::kNeon, DecoderTarget::kScalar};

// The SVE vector length in bytes, 0 without SVE (the kernel's answer; no SVE instruction runs).
std::size_t sve_vector_bytes() noexcept {
#if defined(__aarch64__) && defined(PR_SVE_GET_VL)
  const int vl = ::prctl(PR_SVE_GET_VL, 0, 0, 0, 0);
  return vl < 0 ? 0 : static_cast<std::size_t>(vl & PR_SVE_VL_LEN_MASK);
#else
  return 0;
#endif
}

// ARM64: SVE and SVE2 only where their vectors are wider than NEON's 128 bits. Guest
// instructions per packet counted under QEMU (docs/arm64.md): NEON 9 998; SVE 10 992
// at 128 bits, 7 057 at 256. At 128 bits (Neoverse N2/V2, Grace, Cortex-A710) the SVE kernels
// do NEON's work with predicates on top, so NEON is preferred there.
bool worth_it(DecoderTarget target) noexcept {
  if (target != DecoderTarget::kSve && target != DecoderTarget::kSve2) return true;
  return sve_vector_bytes() > 16;
}

}  // namespace

std::string_view to_string(DecoderTarget target) noexcept {
  for (const auto& [value, name] : kNames) {
    if (value == target) return name;
  }
  return "unknown";
}

std::optional<DecoderTarget> decoder_target_from_string(std::string_view name) noexcept {
  for (const auto& [value, known] : kNames) {
    if (known == name) return value;
  }
  return std::nullopt;
}

std::string join_targets(const std::vector<DecoderTarget>& targets) {
  std::string text;
  for (const DecoderTarget target : targets) {
    if (!text.empty()) text += ", ";
    text += to_string(target);
  }
  return text;
}

DecoderTarget best_decoder_target() {
  const std::vector<DecoderTarget> supported = supported_decoder_targets();
  for (const DecoderTarget target : kAutoPreference) {
    if (std::find(supported.begin(), supported.end(), target) != supported.end() &&
        worth_it(target)) {
      return target;
    }
  }
  return DecoderTarget::kScalar;
}

DecoderChoice choose_decoder_target(std::string_view name) {
  if (name == "auto") return {best_decoder_target(), {}};
  const std::optional<DecoderTarget> target = decoder_target_from_string(name);
  if (!target) {
    return {std::nullopt, "unknown decoder '" + std::string(name) +
                              "' (expected auto, scalar, sse4, avx2, avx512, neon, sve or sve2)"};
  }
  const std::vector<DecoderTarget> supported = supported_decoder_targets();
  if (std::find(supported.begin(), supported.end(), *target) == supported.end()) {
    const std::vector<DecoderTarget> compiled = compiled_decoder_targets();
    const bool built = std::find(compiled.begin(), compiled.end(), *target) != compiled.end();
    return {std::nullopt, "decoder '" + std::string(name) + "': " +
                              (built ? "not supported by this CPU" : "not built into this binary") +
                              " (supported: " + join_targets(supported) + ")"};
  }
  return {target, {}};
}

}  // namespace pandarcap
