// `pandarcap-bench zero-loss --help`: the options and the report's keys (the traffic options
// between the two parts are shared with `send`).
#pragma once

#include <string_view>

namespace pandarcap::bench {

constexpr std::string_view kZeroLossUsageHead = R"(Usage: pandarcap-bench zero-loss [OPTIONS]

Sends Pandar40P packets over loopback (127.0.0.1; or over a veth pair, --veth) with sendmmsg at
paced rates and searches for the highest rate each receiver takes with zero loss: the real
pandarcapd (started per trial with all outputs on), a bare recvmmsg loop and a recvfrom loop. Loss
is counted per stage from the daemon's own health record and cross-checked against the packets
sent.

Where the kernel's delivery work is charged: on loopback and on veth, the receive path (softirq:
IP, UDP, the socket's queue or the packet ring) runs on the sending CPU as the send returns, so it
is in the generator's CPU (generator_cpu_fraction_of_one_core), not in the receivers'; on a real
interface it runs in the NIC's softirq. Each trial's `kernel` says what the machine's softirq time
and the ksoftirqd threads took meanwhile.

Options:
  --json                 print the report as one JSON object (default: the Markdown summary)
  --report-dir DIR       write report.json, summary.md and plot.svg into DIR
  --trial-seconds S      length of each trial (default 10; RFC 2544 uses 60)
  --min-rate PPS         lowest rate tried (default 1000)
  --max-rate PPS         highest rate tried (default 1000000)
  --steps N              bisections between them (default 7)
  --max-gap F            then a trial between any two tested rates more than F times apart
                         (default 2; 0 = none), so the plot joins only neighbouring trials
  --sensor-rate PPS      rate of the CPU/latency/RSS trial (default 3600: one dual-return sensor)
  --daemon FILE          pandarcapd to run (default: the one beside pandarcap-bench)
  --config FILE          daemon configuration (the harness sets address, port and output dir)
  --work-dir DIR         keep daemon logs there (default: a temporary directory in $TMPDIR,
                         else /var/tmp, removed); on ext4 it gets the top-directory flag
                         (chattr +T) so that each trial writes away from files removed nearby.
                         The trials' outputs go at the end, on an error, and on SIGINT, SIGTERM
                         or SIGHUP (each one not ignored when the bench started), with the
                         daemon and tcpdump the bench started
  --daemon-only          skip the reference receivers
  --sensor-rate-only     only the trials at the sensor's rate (no rate search)
  --latency-budget-ms N  the daemon's latency.budget_ms in every trial (default: its own, 5);
                         the sensor-rate trials also run it with 0, for the comparison
  --compare-budget-0     run the zero-loss search again with budget 0 (the same run)
  --compare-mcap         MCAP on vs off in the same run: the sensor-rate trial and the zero-loss
                         search again with --mcap --mcap-packets, with the bytes each wrote
  --sensor-rate-rounds N the bare loop and the daemon at the sensor's rate alternated N times
                         (1, 3, 5, 7 or 9; default 3): daemon_vs_bare_cpu is the median round's, every
                         round in at_sensor_rate.rounds (one trial of each varies by ~25 %
                         on a shared VM); 1 with --daemon-only
  --compare-tcpdump N    N sensor-rate trials with tcpdump -w recording the same packets
                         beside the daemon (/usr/bin/tcpdump, as root): both CPUs, their ratio
  --receiver-command CMD measure another receiver (e.g. a vendor driver) under the same traffic
                         at the sensor's rate: started as /bin/sh -c 'exec CMD', its CPU (all
                         threads) and peak RSS are reported, and, if it prints a line
                         'received N' (N datagrams; the last such line counts, e.g. on SIGTERM),
                         its loss
  --receiver-port N      the UDP port CMD listens on (127.0.0.1; with --veth the near end's
                         address, settings.destination, or 0.0.0.0; required with the command)
  --receiver KIND        the daemon's receiver in every trial: socket (recvmmsg, its default)
                         or packet_ring (AF_PACKET TPACKET_V3 on the interface the packets
                         arrive on: lo, the veth's near end, or --interface; as root)
  --compare-receivers    the sensor-rate trial (with --compare-mcap its MCAP trial, with
                         --compare-tcpdump the tcpdump rounds) with the other receiver too, in
                         the same run: at_sensor_rate.packet_ring (or .socket), the same keys
  --veth                 send over a veth pair the bench makes (as root): the near end
                         pcb<PID>n with 10.231.X.1/30 here, where the daemon, the reference loops
                         and tcpdump receive; the far end pcb<PID>f (.2) in network namespace
                         pandarcap-bench-<PID>, where the generator sends from. Both removed at
                         exit, on an error, and on SIGINT/SIGTERM/SIGHUP
  --interface IFACE      a real interface instead (with --receiver packet_ring or
                         --compare-receivers): the daemon's packet_ring and tcpdump watch IFACE,
                         the daemon and the loops bind 0.0.0.0, and the generator sends to
                         --destination IP, which must arrive on IFACE (an address of this
                         machine goes over lo instead: send to a host that returns the packets,
                         or to IFACE's peer)
  --destination IP       where the generator sends, with --interface
  --from-report FILE     measure nothing: render a saved report.json again (with --report-dir)
)";
constexpr std::string_view kZeroLossUsageTail = R"(  -h, --help             this text

Traffic options apply to every trial. Every packet carries a 4-byte UDP sequence that the
generator writes (0, 1, 2, ...), so loss is exact.

JSON keys (for the --receiver chosen; with --compare-receivers the other one's beside them):
daemon_zero_loss_pps, daemon_loss_at_most_0_5_percent_pps,
bare_recvmmsg_zero_loss_pps, recvfrom_zero_loss_pps, daemon_vs_bare, daemon_vs_recvfrom,
at_sensor_rate {receiver, budget_ms, lost, frames_dropped, pcap_not_recorded, loss_by_stage {kernel_drops,
ring_overruns, rejected, frames_dropped, pcap_packets_not_recorded, write_errors,
mcap_messages_not_written, unaccounted}, cpu_fraction_of_one_core, cpu_us_per_packet, cpu_by_thread,
bare_recvmmsg_cpu_fraction_of_one_core, bare_recvmmsg_generator_cpu_fraction_of_one_core,
daemon_vs_bare_cpu, rounds [{bare_recvmmsg_cpu_fraction_of_one_core,
daemon_cpu_fraction_of_one_core, daemon_vs_bare_cpu, median}], generator_cpu_fraction_of_one_core, kernel
{machine_softirq_cpu_fraction_of_one_core, ksoftirqd_cpu_fraction_of_one_core}, wakeups_per_second {receive, decode,
writer}, frame_latency_p50_ms, frame_latency_p99_ms, latency_p50_us, latency_p99_us,
latency_p999_us, latency_max_us, hot_path_allocations, peak_rss_bytes, written_bytes {pcd,
pcap, mcap}, budget_0 {the same for budget 0}, mcap_on {the same with MCAP on, with
--compare-mcap}, packet_ring or socket {the same, mcap_on, for the other receiver, with
--compare-receivers}, other_receiver {command, cpu_fraction_of_one_core, cpu_us_per_packet,
peak_rss_bytes, received, lost, vs_daemon_cpu}}, daemon_zero_loss_pps_budget_0 (with
--compare-budget-0), mcap_comparison {cpu_fraction_of_one_core_off, cpu_fraction_of_one_core_on,
cpu_on_vs_off, written_mb_per_second_off, written_mb_per_second_on, mcap_mb_per_second,
extra_cpu_us_per_extra_mb, writer_cpu_us_per_written_mb_off, zero_loss_on, peak_rss_bytes_off,
peak_rss_bytes_on, daemon_zero_loss_pps_off, daemon_zero_loss_pps_on, zero_loss_pps_on_vs_off}
(with --compare-mcap), tcpdump_comparison {command, receiver, daemon_cpu_fraction_of_one_core,
tcpdump_cpu_fraction_of_one_core, daemon_vs_tcpdump_cpu, rounds_counted (those whose generator reached 95 % of the rate), rounds, packet_ring or socket {the same,
with --compare-receivers}} (with --compare-tcpdump), goals, environment, settings {receiver,
compared_receiver, path (loopback, veth or interface), interface, destination, sender_namespace,
kernel_delivery, ...}, trials.
Exit status: 0, 1 if the daemon could not be run, 64 for a usage error.
)";

}  // namespace pandarcap::bench
