// PacketRingReceiver's looks at the blocks the kernel has handed over, ahead of taking them:
// when the sensor's newest datagram arrived, how far that is complete, and the kernel's drops
// (the health's last packet and its no_data, daemon/output/writer.cpp).
#include <linux/if_packet.h>
#include <net/if_arp.h>

#include <algorithm>
#include <optional>

#include "core/wire_frame.hpp"
#include "daemon/clocks.hpp"
#include "daemon/source/packet_ring_receiver.hpp"

namespace pandarcap {

void PacketRingReceiver::note_arrivals(ReceiveCounters& counters) noexcept {
  // The blocks handed over since the last look, from where it stopped: each block's packets are
  // newer than the one's before it, so the newest block with a sensor's packet is the one.
  const std::int64_t before_ns = monotonic_ns();
  std::int64_t newest_ns = 0;
  while (arrivals_seen_ < blocks_ahead()) {
    const auto* block = reinterpret_cast<const tpacket_block_desc*>(
        static_cast<const std::uint8_t*>(map_) +
        std::size_t{(next_block_ + arrivals_seen_) % block_count_} * block_bytes_);
    if ((__atomic_load_n(&block->hdr.bh1.block_status, __ATOMIC_ACQUIRE) & TP_STATUS_USER) == 0)
      break;
    newest_ns = std::max(newest_ns, newest_sensor_arrival(*block));
    ++arrivals_seen_;
  }
  if (newest_ns != 0) {
    // What the kernel held in the block it was filling when the ring was last found empty
    // arrived up to a retire period (or two: the timer's) before.
    counters.note_arrival(arrival_on_monotonic(newest_ns, realtime_ns(), monotonic_ns(),
                                               empty_at_ns_, 2'000'000LL * retire_ms_));
  } else if (arrivals_seen_ == 0) {
    empty_at_ns_ = before_ns;  // nothing handed over and not taken
  }
  // With every block handed over, what arrives is dropped (counted), after the newest packet the
  // ring holds: nothing is complete until a block is back with the kernel.
  if (arrivals_seen_ < blocks_ahead()) {
    // A ring that was full held only what arrived until then: the kernel's drops are read (every
    // 10 ms at most, and at the first look after a pause of this thread, whose blocks may have
    // gone back before it), and when there are new ones they arrived before this look: a packet
    // then, for all this side can tell (whose, and whether the sensor stopped since, it cannot).
    if (before_ns >= next_drop_read_ns_) {
      read_statistics(counters);
      next_drop_read_ns_ = before_ns + 10'000'000;
    }
    if (kernel_drops_ != drops_noted_) {
      drops_noted_ = kernel_drops_;
      counters.note_arrival(before_ns);
    }
    // Every block the kernel handed over is seen; what arrived since is in the one it is
    // filling, handed over by its timer (twice its period at most). poll() waits 100 ms at most.
    const std::int64_t retire_ns = 2'000'000LL * retire_ms_;
    counters.note_seen_until(before_ns - retire_ns, 100'000'000 + retire_ns);
  }
}

std::int64_t PacketRingReceiver::newest_sensor_arrival(
    const tpacket_block_desc& block) const noexcept {
  const auto* base = reinterpret_cast<const std::uint8_t*>(&block);
  std::int64_t newest_ns = 0;
  std::uint32_t offset = block.hdr.bh1.offset_to_first_pkt;
  for (std::uint32_t i = 0; i < block.hdr.bh1.num_pkts && offset != 0 && offset < block_bytes_;
       ++i) {
    const auto* header = reinterpret_cast<const tpacket3_hdr*>(base + offset);
    const auto* link = reinterpret_cast<const sockaddr_ll*>(
        reinterpret_cast<const std::uint8_t*>(header) + TPACKET_ALIGN(sizeof(tpacket3_hdr)));
    const std::uint32_t mac_offset = offset + header->tp_mac;
    offset = header->tp_next_offset == 0 ? 0 : offset + header->tp_next_offset;
    if (link->sll_pkttype == PACKET_OUTGOING || link->sll_pkttype == PACKET_OTHERHOST) continue;
    if (mac_offset + std::uint64_t{header->tp_snaplen} > block_bytes_) continue;
    const std::optional<WireFrame> f =
        parse_wire_frame({base + mac_offset, header->tp_snaplen}, header->tp_len);
    if (!f || !sources_.is_sensor_address(f->source_ip)) continue;
    newest_ns = std::int64_t{header->tp_sec} * 1'000'000'000 + std::int64_t{header->tp_nsec};
  }
  return newest_ns;
}

}  // namespace pandarcap
