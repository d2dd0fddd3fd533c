// The PandarQT128 (QT128C2X, protocol 3.2: its manual MAN-QT128; nebula's PandarQT128 decoder and
// Hesai's SDK 2.0 read as the reference; /work/research/hesai-models.md §2.4 has every field
// checked on the real capture, CRCs included).
//
// Layout: what follows the header depends on its flags byte (offset 11), so every offset past the
// blocks comes from layout(flags). The capture's flags are 0x1D (sequence, functional safety,
// signature, confidence): 1127 bytes.
//
//   offset 0       u8[2] EE FF;  2, 3: protocol 3.2;  6: laser count 128;  7: block count 2;
//                  9: distance unit in mm (4);  11: flags: bit 0 UDP sequence, 2 functional
//                  safety (FS), 3 signature, 4 confidence (4-byte units; else 3). Bit 1 (IMU) is
//                  not in Hesai's SDK's size formula and is ignored, as there.
//   offset 12 + (2 + 128u)*b          u16 block azimuth, 0.01°
//   offset 12 + (2 + 128u)*b + 2 + u*c  u16 distance (× unit), u8 reflectivity[, u8 confidence]
//   body CRC       u32 over the two blocks                                  (1040 in the capture)
//   FS (17 bytes)  version, state/counter, fault codes, reserved, u32 CRC over the FS bytes
//                  after the version (the version is outside it: found on the capture)  (1044)
//   tail T (26)    reserved 5, mode flag T+5, reserved 6, return mode T+12, motor speed T+13,
//                  date T+15 (year from 1900), µs T+21, factory T+25                 (1061)
//   sequence       u32, when flagged                                                   (1087)
//   tail CRC       u32 over the tail and the sequence                                  (1091)
//   signature      32 bytes, when flagged; not checked                                 (1095)
//
// CRCs are CRC-32/MPEG-2 (crc32_mpeg2.hpp); a mismatch is bad_crc. nebula checks none of them.
//
// Two firing sequences: each firing fires channels 64-127 and one half of channels 0-63 (the
// other half's units are 0). Sequence 1 fires channels 32-63, sequence 2 channels 0-31. A dual
// packet is one firing, both blocks one sequence, chosen by the tail's mode flag (bit 0 = 1:
// sequence 1); the capture alternates it every packet. A single-return packet is two firings.
// Accessors take the payload bytes and are valid only on a payload validate() accepted.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

#include "core/sensors/crc32_mpeg2.hpp"
#include "core/sensors/model_facts.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap {

struct PandarQT128 : FiringRates<111'110, 2> {
  static constexpr SensorModelId kId = SensorModelId::kPandarQT128;
  static constexpr int kChannels = 128;
  static constexpr int kBlocks = 2;
  static constexpr int kMaxPointsPerPacket = kBlocks * kChannels;  // 256

  static constexpr std::uint8_t kProtocolMajor = 3;
  static constexpr std::uint8_t kProtocolMinor = 2;
  static constexpr std::size_t kHeaderBytes = 12;
  static constexpr std::size_t kLaserCountOffset = 6;
  static constexpr std::size_t kBlockCountOffset = 7;
  static constexpr std::size_t kDistanceUnitOffset = 9;
  static constexpr std::size_t kFlagsOffset = 11;
  static constexpr std::uint8_t kFlagSequence = 0x01;
  static constexpr std::uint8_t kFlagFunctionalSafety = 0x04;
  static constexpr std::uint8_t kFlagSignature = 0x08;
  static constexpr std::uint8_t kFlagConfidence = 0x10;
  static constexpr std::size_t kCrcBytes = 4;
  static constexpr std::size_t kFunctionalSafetyBytes = 17;
  static constexpr std::size_t kTailBytes = 26;
  static constexpr std::size_t kSequenceBytes = 4;
  static constexpr std::size_t kSignatureBytes = 32;
  static constexpr std::size_t kBlockAzimuthOffset = 0;  // inside a block
  static constexpr std::size_t kFirstUnitOffset = 2;     // inside a block
  // Inside the tail.
  static constexpr std::size_t kModeFlagInTail = 5;
  static constexpr std::size_t kReturnModeInTail = 12;
  static constexpr std::size_t kMotorSpeedInTail = 13;
  static constexpr std::size_t kDateTimeInTail = 15;
  static constexpr std::size_t kTimestampInTail = 21;
  static constexpr std::size_t kFactoryInTail = 25;

  // Where everything past the header is, for a flags byte.
  struct Layout {
    std::size_t unit_bytes = 0;       // 4 with the confidence byte, else 3
    std::size_t block_bytes = 0;      // 2 + 128 × unit_bytes
    std::size_t body_crc_offset = 0;  // the CRC covers [kHeaderBytes, body_crc_offset)
    std::optional<std::size_t> functional_safety_offset;  // its CRC: the block's last 4 bytes
    std::size_t tail_offset = 0;
    std::optional<std::size_t> sequence_offset;
    std::size_t tail_crc_offset = 0;  // the CRC covers [tail_offset, tail_crc_offset)
    std::size_t datagram_bytes = 0;   // the signature, when flagged, ends it
  };
  static constexpr Layout layout(std::uint8_t flags) noexcept {
    Layout l;
    l.unit_bytes = (flags & kFlagConfidence) != 0 ? 4 : 3;
    l.block_bytes = 2 + l.unit_bytes * kChannels;
    l.body_crc_offset = kHeaderBytes + kBlocks * l.block_bytes;
    std::size_t at = l.body_crc_offset + kCrcBytes;
    if ((flags & kFlagFunctionalSafety) != 0) {
      l.functional_safety_offset = at;
      at += kFunctionalSafetyBytes;
    }
    l.tail_offset = at;
    at += kTailBytes;
    if ((flags & kFlagSequence) != 0) {
      l.sequence_offset = at;
      at += kSequenceBytes;
    }
    l.tail_crc_offset = at;
    at += kCrcBytes;
    if ((flags & kFlagSignature) != 0) at += kSignatureBytes;
    l.datagram_bytes = at;
    return l;
  }
  static Layout layout(std::span<const std::uint8_t> p) noexcept { return layout(p[kFlagsOffset]); }
  // The lengths flags combinations give run from 818 (nothing optional, 3-byte units) to this,
  // everything present (checked below the class).
  static constexpr std::size_t kMaxDatagramBytes = 1127;

  // The sensor's own range (nebula's PandarQT128: 0.05-50 m).
  static constexpr double kMinRangeM = 0.05;
  static constexpr double kMaxRangeM = 50.0;
  // 600 RPM: no other speed is documented for the QT128 (hesai-models.md §6).
  static constexpr std::array<int, 1> kSupportedRpms = {600};
  // nebula's QT128 modes (single first, strongest, last; dual last + strongest, first + last,
  // first + strongest).
  static constexpr std::array<ReturnMode, 6> kReturnModes = {
      ReturnMode::kFirst, ReturnMode::kStrongest, ReturnMode::kLast,
      ReturnMode::kDual,  ReturnMode::kFirstLast, ReturnMode::kFirstStrongest};

  // The nominal table: the QT128's correction file as Hesai ships it (nebula's
  // calibration/PandarQT128.csv, the same bytes as the capture's nebula_PandarQT128_calibration
  // .csv). No design table from the manual was at hand; this one is computed from the design,
  // not measured on a unit: channels 97-128 are channels 32-1 with elevation and azimuth negated
  // to every one of their 8-10 decimals, which no measurement would give. Channel 1 is the
  // bottom (-52.6°), channel 128 the top.
  static constexpr std::array<double, kChannels> kNominalElevationDeg = {
      -52.62676282, -51.0280939,  -49.51495392, -48.07394795, -46.69466297, -45.36882812,
      -44.08974439, -42.85190128, -41.65069769, -40.48225401, -39.34326358, -38.23088092,
      -37.14263654, -36.07637316, -35.03019446, -34.00242585, -32.99157758, -31.99631045,
      -31.01543179, -30.04786472, -29.09262707, -28.14883195, -27.21566989, -26.29240356,
      -25.37835081, -24.47288318, -23.57542315, -22.68544071, -21.80243688, -20.92594329,
      -20.05553602, -19.19081372, -18.33139172, -17.47691901, -16.62705442, -15.78149317,
      -14.93993032, -14.10208035, -13.26767188, -12.43645574, -11.60818201, -10.78261371,
      -9.959523504, -9.138697037, -8.319929599, -7.503005408, -6.687807162, -5.873926875,
      -5.061393513, -4.249948322, -3.43941536,  -2.629617595, -1.820378325, -1.011522452,
      -0.202883525, 0.605717878,  1.414444374,  2.223469054,  3.032962884,  3.8431104,
      4.654074511,  5.466034723,  6.279180222,  7.093696848,  7.909760474,  8.727579858,
      9.54735011,   10.36927364,  11.19356846,  12.0204614,   12.85016831,  13.68294669,
      14.51903314,  15.35869922,  16.20222125,  17.04988688,  17.90200196,  18.75890049,
      19.62091911,  20.48842178,  21.36180725,  22.24149217,  23.12791172,  24.02155359,
      24.92293181,  25.83260224,  26.75116558,  27.67927338,  28.61763387,  29.56702472,
      30.52828971,  31.50236238,  32.49026442,  33.49313666,  34.51223682,  35.54897914,
      19.19081372,  20.05553602,  20.92594329,  21.80243688,  22.68544071,  23.57542315,
      24.47288318,  25.37835081,  26.29240356,  27.21566989,  28.14883195,  29.09262707,
      30.04786472,  31.01543179,  31.99631045,  32.99157758,  34.00242585,  35.03019446,
      36.07637316,  37.14263654,  38.23088092,  39.34326358,  40.48225401,  41.65069769,
      42.85190128,  44.08974439,  45.36882812,  46.69466297,  48.07394795,  49.51495392,
      51.0280939,   52.62676282,
  };
  static constexpr std::array<double, kChannels> kNominalAzimuthOffsetDeg = {
      10.10830596,  9.719503673,  9.384265827,  9.091433335,  8.832899657,  8.602605729,
      8.395920495,  8.209210679,  8.03961095,   7.8848012,    7.742887867,  7.612311759,
      7.491771683,  7.380164213,  7.276562397,  7.180171603,  7.090302002,  7.006369095,
      6.927848973,  6.854295551,  6.785306938,  6.720536921,  6.659666871,  6.602428464,
      6.548569874,  6.497872808,  6.450129948,  6.405178951,  6.362840261,  6.32298504,
      6.285467298,  6.25017485,   -6.21699538,  -6.18583344,  -6.156599148, -6.129208192,
      -6.103581848, -6.079663981, -6.057381402, -6.036683527, -6.017519726, -5.999833659,
      -5.983597281, -5.968771181, -5.955310246, -5.943192006, -5.926719867, -5.922876604,
      -5.914628713, -5.907639071, -5.901885097, -5.897355529, -5.894039091, -5.891935825,
      -5.89103442,  -5.89132922,  -5.892831558, -5.895541414, -5.899458754, -5.904600534,
      -5.910966684, -5.918579795, -5.927451101, -5.937608821, 5.949064148,  5.961845258,
      5.97598597,   5.99150874,   6.008464331,  6.026875139,  6.046797524,  6.068282136,
      6.091373918,  6.116134758,  6.142626487,  6.170927865,  6.201111915,  6.233268566,
      6.267487655,  6.303870236,  6.342539884,  6.383614369,  6.427233938,  6.473555624,
      6.52274755,   6.574994555,  6.63050945,   6.689521655,  6.752299732,  6.819128697,
      6.890343815,  6.966319159,  7.0474731,    7.134285032,  7.227334588,  7.327222327,
      -6.25017485,  -6.285467298, -6.32298504,  -6.362840261, -6.405178951, -6.450129948,
      -6.497872808, -6.548569874, -6.602428464, -6.659666871, -6.720536921, -6.785306938,
      -6.854295551, -6.927848973, -7.006369095, -7.090302002, -7.180171603, -7.276562397,
      -7.380164213, -7.491771683, -7.612311759, -7.742887867, -7.8848012,   -8.03961095,
      -8.209210679, -8.395920495, -8.602605729, -8.832899657, -9.091433335, -9.384265827,
      -9.719503673, -10.10830596,
  };

  // Firing times (ns) of each channel after its firing's start, per sequence; 0: the channel
  // does not fire in that sequence (MAN-QT128 p.36; nebula's loop1 and loop2).
  static constexpr std::array<std::int32_t, kChannels> kSequence1Ns = {
      0,     0,     0,     0,     0,      0,     0,     0,      // 0..7
      0,     0,     0,     0,     0,      0,     0,     0,      // 8..15
      0,     0,     0,     0,     0,      0,     0,     0,      // 16..23
      0,     0,     0,     0,     0,      0,     0,     0,      // 24..31
      27656, 53000, 2312,  78344, 81512,  5480,  56168, 30824,  // 32..39
      33992, 59336, 8648,  84680, 87848,  11816, 62504, 37160,  // 40..47
      40328, 65672, 14984, 91016, 94184,  18152, 68840, 43496,  // 48..55
      46664, 72008, 21320, 97352, 100520, 24488, 75176, 49832,  // 56..63
      1456,  77488, 26800, 52144, 55312,  29968, 80656, 4624,   // 64..71
      7792,  83824, 33136, 58480, 61648,  36304, 86992, 10960,  // 72..79
      14128, 90160, 39472, 64816, 67984,  42640, 93328, 17296,  // 80..87
      20464, 96496, 45808, 71152, 74320,  48976, 99664, 23632,  // 88..95
      25944, 51288, 600,   76632, 79800,  3768,  54456, 29112,  // 96..103
      32280, 57624, 6936,  82968, 86136,  10104, 60792, 35448,  // 104..111
      38616, 63960, 13272, 89304, 92472,  16440, 67128, 41784,  // 112..119
      44952, 70296, 19608, 95640, 98808,  22776, 73464, 48120,  // 120..127
  };
  static constexpr std::array<std::int32_t, kChannels> kSequence2Ns = {
      2312,  78344, 27656, 53000, 56168, 30824, 81512,  5480,   // 0..7
      8648,  84680, 33992, 59336, 62504, 37160, 87848,  11816,  // 8..15
      14984, 91016, 40328, 65672, 68840, 43496, 94184,  18152,  // 16..23
      21320, 97352, 46664, 72008, 75176, 49832, 100520, 24488,  // 24..31
      0,     0,     0,     0,     0,     0,     0,      0,      // 32..39
      0,     0,     0,     0,     0,     0,     0,      0,      // 40..47
      0,     0,     0,     0,     0,     0,     0,      0,      // 48..55
      0,     0,     0,     0,     0,     0,     0,      0,      // 56..63
      600,   76632, 25944, 51288, 54456, 29112, 79800,  3768,   // 64..71
      6936,  82968, 32280, 57624, 60792, 35448, 86136,  10104,  // 72..79
      13272, 89304, 38616, 63960, 67128, 41784, 92472,  16440,  // 80..87
      19608, 95640, 44952, 70296, 73464, 48120, 98808,  22776,  // 88..95
      26800, 52144, 1456,  77488, 80656, 4624,  55312,  29968,  // 96..103
      33136, 58480, 7792,  83824, 86992, 10960, 61648,  36304,  // 104..111
      39472, 64816, 14128, 90160, 93328, 17296, 67984,  42640,  // 112..119
      45808, 71152, 20464, 96496, 99664, 23632, 74320,  48976,  // 120..127
  };
  static constexpr std::int64_t kFirstFiringNs = 9'000;  // a packet's first firing starts here

  // EE FF; protocol 3.2, laser count 128, block count 2 (else wrong_model); the length its
  // flags give; the body, FS and tail CRCs (bad_crc); azimuths < 36000; a return mode of
  // kReturnModes.
  static RejectReason validate(std::span<const std::uint8_t> p) noexcept {
    if (p.size() < kHeaderBytes) return RejectReason::kBadLength;
    if (p[0] != 0xEE || p[1] != 0xFF) return RejectReason::kBadMarker;
    if (p[2] != kProtocolMajor || p[3] != kProtocolMinor || p[kLaserCountOffset] != kChannels ||
        p[kBlockCountOffset] != kBlocks) {
      return RejectReason::kWrongModel;
    }
    const Layout l = layout(p);
    if (p.size() != l.datagram_bytes) return RejectReason::kBadLength;
    if (!crc_matches(p, kHeaderBytes, l.body_crc_offset) ||
        (l.functional_safety_offset &&
         !crc_matches(p, *l.functional_safety_offset + 1,
                      *l.functional_safety_offset + kFunctionalSafetyBytes - kCrcBytes)) ||
        !crc_matches(p, l.tail_offset, l.tail_crc_offset)) {
      return RejectReason::kBadCrc;
    }
    for (int b = 0; b < kBlocks; ++b) {
      if (azimuth_cdeg(p, b) >= kAzimuthLimitCdeg) return RejectReason::kBadAzimuth;
    }
    const auto mode = return_mode_from_byte(p[l.tail_offset + kReturnModeInTail]);
    if (!mode || !mode_listed(kReturnModes, *mode)) return RejectReason::kBadReturnMode;
    return RejectReason::kNone;
  }
  // Writes the three CRCs of a packet whose length matches its flags (a simulator's, a test's).
  static void write_crcs(std::span<std::uint8_t> p) noexcept {
    const Layout l = layout(p[kFlagsOffset]);
    store_crc(p, kHeaderBytes, l.body_crc_offset);
    if (l.functional_safety_offset) {
      store_crc(p, *l.functional_safety_offset + 1,
                *l.functional_safety_offset + kFunctionalSafetyBytes - kCrcBytes);
    }
    store_crc(p, l.tail_offset, l.tail_crc_offset);
  }

  static const std::uint8_t* block(std::span<const std::uint8_t> p, int b) noexcept {
    return p.data() + kHeaderBytes + layout(p).block_bytes * static_cast<std::size_t>(b);
  }
  static std::size_t unit_offset(std::span<const std::uint8_t> p, int c) noexcept {
    return kFirstUnitOffset + layout(p).unit_bytes * static_cast<std::size_t>(c);
  }
  static std::uint16_t azimuth_cdeg(std::span<const std::uint8_t> p, int b) noexcept {
    return load_u16_le(block(p, b) + kBlockAzimuthOffset);
  }
  static std::uint16_t distance_raw(std::span<const std::uint8_t> p, int b, int c) noexcept {
    return load_u16_le(block(p, b) + unit_offset(p, c));
  }
  static std::uint8_t reflectivity(std::span<const std::uint8_t> p, int b, int c) noexcept {
    return block(p, b)[unit_offset(p, c) + 2];
  }
  static double distance_unit_m(std::span<const std::uint8_t> p) noexcept {
    return p[kDistanceUnitOffset] * 1e-3;
  }
  static const std::uint8_t* tail(std::span<const std::uint8_t> p) noexcept {
    return p.data() + layout(p).tail_offset;
  }
  static std::uint8_t mode_flag(std::span<const std::uint8_t> p) noexcept {
    return tail(p)[kModeFlagInTail];
  }
  static std::uint16_t motor_rpm(std::span<const std::uint8_t> p) noexcept {
    return load_u16_le(tail(p) + kMotorSpeedInTail);
  }
  static std::uint32_t timestamp_us(std::span<const std::uint8_t> p) noexcept {
    return load_u32_le(tail(p) + kTimestampInTail);
  }
  static ReturnMode return_mode(std::span<const std::uint8_t> p) noexcept {
    return static_cast<ReturnMode>(tail(p)[kReturnModeInTail]);
  }
  static std::uint8_t factory(std::span<const std::uint8_t> p) noexcept {
    return tail(p)[kFactoryInTail];
  }
  // The QT128's tail has no shutdown flag (MAN-QT128's tail: reserved bytes there); its faults
  // are in the functional-safety block (functional_safety_state()).
  static bool high_temperature(std::span<const std::uint8_t>) noexcept { return false; }
  // The FS block's lidar state (bits 7-5 of its second byte: 0-2 fine, 3 warning, 4+ fault, as
  // nebula reads it) and rolling counter (bits 2-0); nullopt without the block.
  static std::optional<std::uint8_t> functional_safety_state(
      std::span<const std::uint8_t> p) noexcept {
    const auto at = layout(p).functional_safety_offset;
    if (!at) return std::nullopt;
    return static_cast<std::uint8_t>(p[*at + 1] >> 5);
  }
  static std::optional<std::uint8_t> functional_safety_counter(
      std::span<const std::uint8_t> p) noexcept {
    const auto at = layout(p).functional_safety_offset;
    if (!at) return std::nullopt;
    return static_cast<std::uint8_t>(p[*at + 1] & 0x07);
  }
  static std::optional<std::uint32_t> sequence(std::span<const std::uint8_t> p) noexcept {
    const auto at = layout(p).sequence_offset;
    if (!at) return std::nullopt;
    return load_u32_le(p.data() + *at);
  }
  // MAN-QT128: year counted from 1900 (the capture's raw 120 = 2020).
  static constexpr std::uint16_t year_from_raw(std::uint8_t raw) noexcept {
    return static_cast<std::uint16_t>(1900 + raw);
  }
  static PacketDateTime utc(std::span<const std::uint8_t> p) noexcept {
    const std::uint8_t* t = tail(p) + kDateTimeInTail;
    return {year_from_raw(t[0]), t[1], t[2], t[3], t[4], t[5]};
  }

  // Which sequence (1 or 2) fired block `block`: Hesai's SDK rule, (mode flag + firing + 1) mod 2
  // with firing = block / returns, 0 meaning sequence 1. Dual: both blocks one firing, sequence 1
  // when bit 0 of the mode flag is set (the capture: channels 32-63 zero when it is 0, channels
  // 0-31 zero when it is 1). Single: the two blocks are two firings in turn; with the flag at 1,
  // block 0 is sequence 1, as MAN-QT128 and nebula have it (the flag's value in single return is
  // unverified: no capture).
  static constexpr int firing_sequence(std::uint8_t mode_flag, int block, int returns) noexcept {
    return ((mode_flag & 0x01) + block / returns + 1) % 2 == 0 ? 1 : 2;
  }
  static constexpr bool fires(int sequence, int channel) noexcept {
    return (sequence == 1 ? kSequence1Ns : kSequence2Ns)[static_cast<std::size_t>(channel)] != 0;
  }
  // When channel `channel` of block `block` fired, relative to the packet's time (ns): the SDK's
  // (and the manual's) semantics, 9 µs + 111.11 µs × firing + the channel's time in its sequence,
  // both blocks of a dual packet one firing. nebula computes 111110 × (1 - block) / returns
  // instead (multiplication before the division), which puts a dual packet's block 0 55.6 µs
  // after its block 1 and a single packet's block 0 111 µs after its block 1: a precedence slip,
  // not the sensor (hesai-models.md §3.2). Its timestamps differ from these; its x, y, z do not.
  static constexpr std::int64_t firing_offset_ns(int block, int channel, int returns,
                                                 std::uint8_t mode_flag) noexcept {
    const int sequence = firing_sequence(mode_flag, block, returns);
    return kFirstFiringNs + kFiringPeriodNs * (block / returns) +
           (sequence == 1 ? kSequence1Ns : kSequence2Ns)[static_cast<std::size_t>(channel)];
  }
  static std::int64_t firing_offset_ns(std::span<const std::uint8_t> p, int block, int channel,
                                       int returns) noexcept {
    return firing_offset_ns(block, channel, returns, mode_flag(p));
  }

 private:
  static bool crc_matches(std::span<const std::uint8_t> p, std::size_t begin,
                          std::size_t end) noexcept {
    return crc32_mpeg2(p.subspan(begin, end - begin)) == load_u32_le(p.data() + end);
  }
  static void store_crc(std::span<std::uint8_t> p, std::size_t begin, std::size_t end) noexcept {
    const std::uint32_t crc =
        crc32_mpeg2(std::span<const std::uint8_t>(p).subspan(begin, end - begin));
    for (std::size_t i = 0; i < kCrcBytes; ++i)
      p[end + i] = static_cast<std::uint8_t>(crc >> (8 * i));
  }
};

static_assert(PandarQT128::layout(PandarQT128::kFlagSequence | PandarQT128::kFlagFunctionalSafety |
                                  PandarQT128::kFlagSignature | PandarQT128::kFlagConfidence)
                  .datagram_bytes == PandarQT128::kMaxDatagramBytes);

}  // namespace pandarcap
