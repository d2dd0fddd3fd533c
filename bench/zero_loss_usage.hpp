// `pandarcap-bench zero-loss --help`: the options and the report's keys (the traffic options
// between the two parts are shared with `send`).
#pragma once

#include <string_view>

namespace pandarcap::bench {

constexpr std::string_view kZeroLossUsageHead = R"(Usage: pandarcap-bench zero-loss [OPTIONS]

Sends Pandar40P packets over loopback (127.0.0.1) with sendmmsg at paced rates and searches for
the highest rate each receiver takes with zero loss: the real pandarcapd (started per trial with
all outputs on), a bare recvmmsg loop and a recvfrom loop. Loss is counted per stage from the
daemon's own health record and cross-checked against the packets sent.

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
  --work-dir DIR         keep daemon logs there (default: a temporary directory, removed)
  --daemon-only          skip the reference receivers
  --sensor-rate-only     only the trials at the sensor's rate (no rate search)
  --latency-budget-ms N  the daemon's latency.budget_ms in every trial (default: its own, 5);
                         the sensor-rate trials also run it with 0, for the comparison
  --compare-budget-0     run the zero-loss search again with budget 0 (the same run)
  --compare-mcap         MCAP on vs off in the same run: the sensor-rate trial and the zero-loss
                         search again with --mcap --mcap-packets, with the bytes each wrote
  --compare-tcpdump N    N sensor-rate trials with tcpdump -w recording the same packets
                         beside the daemon (/usr/bin/tcpdump, as root): both CPUs, their ratio
  --receiver-command CMD measure another receiver (e.g. a vendor driver) under the same traffic
                         at the sensor's rate: started as /bin/sh -c 'exec CMD', its CPU (all
                         threads) and peak RSS are reported, and, if it prints a line
                         'received N' (N datagrams; the last such line counts, e.g. on SIGTERM),
                         its loss
  --receiver-port N      the UDP port CMD listens on (127.0.0.1; required with the command)
  --from-report FILE     measure nothing: render a saved report.json again (with --report-dir)
)";
constexpr std::string_view kZeroLossUsageTail = R"(  -h, --help             this text

Traffic options apply to every trial. Every packet carries a 4-byte UDP sequence that the
generator writes (0, 1, 2, ...), so loss is exact.

JSON keys: daemon_zero_loss_pps, daemon_loss_at_most_0_5_percent_pps,
bare_recvmmsg_zero_loss_pps, recvfrom_zero_loss_pps, daemon_vs_bare, daemon_vs_recvfrom,
at_sensor_rate {budget_ms, lost, frames_dropped, pcap_not_recorded, loss_by_stage {kernel_drops,
ring_overruns, rejected, frames_dropped, pcap_packets_not_recorded, write_errors,
mcap_messages_not_written, unaccounted}, cpu_fraction_of_one_core, cpu_us_per_packet, cpu_by_thread,
bare_recvmmsg_cpu_fraction_of_one_core, daemon_vs_bare_cpu, wakeups_per_second {receive, decode,
writer}, frame_latency_p50_ms, frame_latency_p99_ms, latency_p50_us, latency_p99_us,
latency_p999_us, latency_max_us, hot_path_allocations, peak_rss_bytes, written_bytes {pcd,
pcap, mcap}, budget_0 {the same for budget 0}, mcap_on {the same with MCAP on, with
--compare-mcap}, other_receiver {command, cpu_fraction_of_one_core, cpu_us_per_packet,
peak_rss_bytes, received, lost, vs_daemon_cpu}}, daemon_zero_loss_pps_budget_0 (with
--compare-budget-0), mcap_comparison {cpu_fraction_of_one_core_off, cpu_fraction_of_one_core_on,
cpu_on_vs_off, written_mb_per_second_off, written_mb_per_second_on, mcap_mb_per_second,
extra_cpu_us_per_extra_mb, writer_cpu_us_per_written_mb_off, zero_loss_on, peak_rss_bytes_off,
peak_rss_bytes_on, daemon_zero_loss_pps_off, daemon_zero_loss_pps_on, zero_loss_pps_on_vs_off}
(with --compare-mcap), tcpdump_comparison {daemon_cpu_fraction_of_one_core,
tcpdump_cpu_fraction_of_one_core, daemon_vs_tcpdump_cpu, rounds} (with --compare-tcpdump), goals, environment, settings, trials.
Exit status: 0, 1 if the daemon could not be run, 64 for a usage error.
)";

}  // namespace pandarcap::bench
