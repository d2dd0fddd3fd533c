// The zero-loss report as a person reads it: a Markdown summary and an SVG plot.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "bench/zero_loss.hpp"

namespace pandarcap::bench {

namespace {

using nlohmann::ordered_json;

std::string rate(double pps) {
  if (pps >= 1e6) return fmt::format("{:.2f} M", pps / 1e6);
  if (pps >= 1e3) return fmt::format("{:.1f} k", pps / 1e3);
  return fmt::format("{:.0f}", pps);
}

std::string yes_no(const ordered_json& v) {
  return v.get<bool>() ? "met" : "**not met**";
}

// One plotted series: (achieved, value) points in achieved order. The x of a trial is the rate
// the generator really sent (achieved_pps), not the one it was asked for: on a busy machine the
// two differ, and the plot must not credit a receiver with a rate it was never sent.
struct Series {
  std::string name, colour;
  std::vector<std::pair<double, double>> points;
};

// A trial's x: what was sent (reports from before achieved_pps was kept: what was offered).
double sent_rate(const ordered_json& t) {
  return t.contains("achieved_pps") ? t.at("achieved_pps").get<double>()
                                    : t.at("offered_pps").get<double>();
}

Series series(const ordered_json& trials, const std::string& name, const std::string& colour,
              const std::string& y_key) {
  Series s{name, colour, {}};
  for (const auto& t : trials) {
    if (t.contains(y_key)) s.points.emplace_back(sent_rate(t), t.at(y_key).get<double>());
  }
  std::sort(s.points.begin(), s.points.end());
  return s;
}

// Series names in their colours, one per line from (x, 60).
void legend(std::string& svg, const std::vector<Series>& series, int x) {
  for (std::size_t i = 0; i < series.size(); ++i) {
    svg += fmt::format(R"(<text x="{}" y="{}" font-size="12" fill="{}">{}</text>)"
                       "\n",
                       x, 60 + 16 * i, series[i].colour, series[i].name);
  }
}

class Panel {
 public:
  Panel(double x0, double y0, double w, double h, double xmin, double xmax, double ymin,
        double ymax, bool log_y)
      : x0_(x0),
        y0_(y0),
        w_(w),
        h_(h),
        lx0_(std::log10(xmin)),
        lx1_(std::log10(xmax)),
        ymin_(ymin),
        ymax_(ymax),
        log_y_(log_y) {}
  double x(double v) const { return x0_ + (std::log10(v) - lx0_) / (lx1_ - lx0_) * w_; }
  double y(double v) const {
    const double f = log_y_ ? (std::log10(std::max(v, ymin_)) - std::log10(ymin_)) /
                                  (std::log10(ymax_) - std::log10(ymin_))
                            : (v - ymin_) / (ymax_ - ymin_);
    return y0_ + h_ - std::clamp(f, 0.0, 1.0) * h_;
  }
  void frame(std::string& svg, const std::string& title, const std::string& ylabel) const {
    svg += fmt::format(R"(<rect x="{}" y="{}" width="{}" height="{}" fill="none" stroke="#444"/>)"
                       "\n",
                       x0_, y0_, w_, h_);
    svg += fmt::format(R"(<text x="{}" y="{}" font-size="14" text-anchor="middle">{}</text>)"
                       "\n",
                       x0_ + w_ / 2, y0_ - 8, title);
    svg += fmt::format(
        R"(<text x="{}" y="{}" font-size="12" text-anchor="middle">sent packets/s (achieved)</text>)"
        "\n",
        x0_ + w_ / 2, y0_ + h_ + 32);
    svg += fmt::format(
        R"svg(<text x="{}" y="{}" font-size="12" text-anchor="middle" transform="rotate(-90 {} {})">{}</text>)svg"
        "\n",
        x0_ - 60, y0_ + h_ / 2, x0_ - 60, y0_ + h_ / 2, ylabel);
    // y ticks: decades on a log axis, fifths on a linear one (a percentage here).
    if (log_y_) {
      for (double d = std::ceil(std::log10(ymin_)); d <= std::log10(ymax_); d += 1) {
        const double v = std::pow(10, d);
        svg += fmt::format(R"(<line x1="{0}" y1="{1}" x2="{2}" y2="{1}" stroke="#ddd"/>)"
                           R"(<text x="{3}" y="{4}" font-size="11" text-anchor="end">{5}</text>)"
                           "\n",
                           x0_, y(v), x0_ + w_, x0_ - 4, y(v) + 4, rate(v));
      }
    } else {
      for (int k = 0; k <= 5; ++k) {
        const double v = ymin_ + (ymax_ - ymin_) * k / 5;
        svg +=
            fmt::format(R"(<line x1="{0}" y1="{1}" x2="{2}" y2="{1}" stroke="#ddd"/>)"
                        R"(<text x="{3}" y="{4}" font-size="11" text-anchor="end">{5:.1f}</text>)"
                        "\n",
                        x0_, y(v), x0_ + w_, x0_ - 4, y(v) + 4, v);
      }
    }
    for (double d = std::ceil(lx0_); d <= lx1_; d += 1) {
      const double v = std::pow(10, d);
      svg += fmt::format(R"(<line x1="{0}" y1="{1}" x2="{0}" y2="{2}" stroke="#ddd"/>)"
                         R"(<text x="{0}" y="{3}" font-size="11" text-anchor="middle">{4}</text>)"
                         "\n",
                         x(v), y0_, y0_ + h_, y0_ + h_ + 14, rate(v));
    }
  }
  // Markers at the trials, joined only where neighbours are within `join_ratio` of each other
  // in rate: across a wider gap nothing was measured, and a line would pretend it was.
  void plot(std::string& svg, const Series& s, double join_ratio = 2.5) const {
    if (s.points.empty()) return;
    std::string path;
    const auto flush = [&] {
      if (path.find(' ') != path.rfind(' ')) {  // two points or more
        svg += fmt::format(R"(<polyline points="{}" fill="none" stroke="{}" stroke-width="2"/>)"
                           "\n",
                           path, s.colour);
      }
      path.clear();
    };
    for (std::size_t i = 0; i < s.points.size(); ++i) {
      if (i > 0 && s.points[i].first > join_ratio * s.points[i - 1].first) flush();
      path += fmt::format("{:.1f},{:.1f} ", x(s.points[i].first), y(s.points[i].second));
    }
    flush();
    for (const auto& [px, py] : s.points) {
      svg += fmt::format(R"(<circle cx="{:.1f}" cy="{:.1f}" r="3" fill="{}"/>)"
                         "\n",
                         x(px), y(py), s.colour);
    }
  }

 private:
  double x0_, y0_, w_, h_, lx0_, lx1_, ymin_, ymax_;
  bool log_y_;
};

// "0.42 cores", or "-" for a trial from a report that did not measure it.
std::string cores(double fraction) {
  return fraction < 0 ? "-" : fmt::format("{:.2f} cores", fraction);
}

// The stages at which a trial's packets were not fully handled, with their counts ("-": none).
std::string not_done(const ordered_json& t) {
  std::string out;
  if (t.contains("loss_by_stage")) {
    for (const auto& [stage, n] : t.at("loss_by_stage").items()) {
      if (n.get<std::uint64_t>() > 0)
        out += fmt::format("{}{} {}", out.empty() ? "" : ", ", stage, n.dump());
    }
  } else if (t.value("kernel_drops", std::uint64_t{0}) > 0) {
    out = "kernel_drops " + t.at("kernel_drops").dump();
  }
  return out.empty() ? "-" : out;
}

// A count a sensor-rate summary carries, "-" in a report from before it did.
std::string count(const ordered_json& t, const char* key) {
  return t.contains(key) ? t.at(key).dump() : std::string("-");
}

// The daemon against tcpdump -w recording the same packets beside it, with one receiver.
std::string tcpdump_table(const ordered_json& r, const ordered_json& c, const std::string& goal) {
  std::string md = fmt::format(
      "Recording against `tcpdump -w` beside it (the same packets, the same seconds; config: "
      "{}{}):\n\n| round | pandarcapd CPU (% of a core) | tcpdump CPU | ratio | pcap bytes "
      "(pandarcapd, tcpdump) | lost, not recorded (pandarcapd) | dropped (tcpdump) |\n"
      "|---:|---:|---:|---:|---:|---:|---:|\n",
      r.at("environment").at("daemon_config").get<std::string>(),
      c.contains("receiver") ? "; receiver: " + c.at("receiver").get<std::string>() : "");
  int round = 0;
  for (const auto& t : c.at("rounds")) {
    md += fmt::format("| {} | {:.2f} | {:.2f} | {:.2f}x | {}, {} | {}, {} | {} |\n", ++round,
                      100 * t.at("daemon_cpu_fraction_of_one_core").get<double>(),
                      100 * t.at("tcpdump_cpu_fraction_of_one_core").get<double>(),
                      t.at("daemon_vs_tcpdump_cpu").get<double>(), t.at("daemon_pcap_bytes").dump(),
                      t.at("tcpdump_file_bytes").dump(), t.at("daemon_lost").dump(),
                      t.at("daemon_pcap_not_recorded").dump(),
                      t.at("tcpdump_dropped_by_kernel").dump());
  }
  md += fmt::format(
      "\nOver all rounds: pandarcapd {:.2f} %, tcpdump {:.2f} % of a core: **{:.2f}x** (goal "
      "<= 1: {}).\n\n",
      100 * c.at("daemon_cpu_fraction_of_one_core").get<double>(),
      100 * c.at("tcpdump_cpu_fraction_of_one_core").get<double>(),
      c.at("daemon_vs_tcpdump_cpu").get<double>(), yes_no(r.at("goals").at(goal)));
  return md;
}

// ... with the receiver chosen, and the other one's when both were measured ("" without it).
std::string tcpdump_section(const ordered_json& r) {
  if (!r.contains("tcpdump_comparison")) return {};
  const auto& c = r.at("tcpdump_comparison");
  std::string md = tcpdump_table(r, c, "cpu_recording_at_most_tcpdump_w");
  for (const char* other : {"socket", "packet_ring"}) {
    if (c.contains(other)) {
      md += tcpdump_table(r, c.at(other), std::string("cpu_recording_at_most_tcpdump_w_") + other);
    }
  }
  return md;
}

// Which path the packets took, the daemon's receiver, and where the kernel's delivery work was
// charged ("" in a report from before the paths).
std::string path_line(const ordered_json& r) {
  const auto& settings = r.at("settings");
  if (!settings.contains("path")) return {};
  std::string md = fmt::format("Path: **{}** (packets arrive on {}); the daemon's receiver: **{}**",
                               settings.at("path").get<std::string>(),
                               settings.at("interface").get<std::string>(),
                               settings.at("receiver").get<std::string>());
  if (settings.at("compared_receiver").is_string()) {
    md += fmt::format(", and {} beside it", settings.at("compared_receiver").get<std::string>());
  }
  md += ". " + settings.at("kernel_delivery").get<std::string>() + "\n\n";
  return md;
}

// Where the daemon's search stopped, in CPU: at the lowest rate it failed, what the generator
// and the daemon's threads used against the cores there are. On a machine whose cores the sender
// shares, this is the budget the daemon ran out of.
std::string cpu_budget(const ordered_json& r) {
  const ordered_json* lowest_failed = nullptr;
  for (const auto& t : r.at("trials").at("daemon")) {
    if (t.value("passed", true) || !t.contains("generator_cpu_fraction_of_one_core")) continue;
    if (!lowest_failed || t.at("offered_pps") < (*lowest_failed).at("offered_pps"))
      lowest_failed = &t;
  }
  if (!lowest_failed) return {};
  const ordered_json& t = *lowest_failed;
  std::string threads;
  for (const auto& [name, u] : t.at("cpu_by_thread").items()) {
    const double f = u.at("cpu_fraction_of_one_core").get<double>();
    if (f >= 0.005) threads += fmt::format("{}{} {:.2f}", threads.empty() ? "" : ", ", name, f);
  }
  const double generator = t.at("generator_cpu_fraction_of_one_core").get<double>();
  const double daemon = t.at("cpu_fraction_of_one_core").get<double>();
  return fmt::format(
      "CPU at the lowest rate the daemon failed ({} packets/s; {}): the generator used {:.2f} "
      "of a core (sending, and the kernel's loopback delivery, which runs in the sender), the "
      "daemon {:.2f} ({}): {:.2f} of the {} cores, before the kernel's own writeback of the "
      "files.\n\n",
      rate(t.at("offered_pps").get<double>()), not_done(t), generator, daemon, threads,
      generator + daemon, r.at("environment").value("cores", 0));
}

}  // namespace

std::string zero_loss_markdown(const ordered_json& r) {
  const auto& s = r.at("at_sensor_rate");
  const auto& g = r.at("goals");
  const auto& env = r.at("environment");
  std::string md = "# pandarcap zero-loss benchmark\n\n";
  md +=
      fmt::format("Machine: {} ({} cores), {}, rmem_max {}; commit {}, {} build.\n\n",
                  env.at("cpu_model").get<std::string>(), env.at("cores").get<int>(),
                  env.at("kernel").get<std::string>(), env.at("rmem_max").get<std::uint64_t>(),
                  env.at("git_commit").get<std::string>(), env.at("build_type").get<std::string>());
  md += fmt::format("Traffic: {}; trials of {} s; search {}..{} packets/s.\n\n",
                    r.at("settings").at("traffic").get<std::string>(),
                    r.at("settings").at("trial_seconds").get<double>(),
                    rate(r.at("settings").at("min_rate").get<double>()),
                    rate(r.at("settings").at("max_rate").get<double>()));
  md += path_line(r);
  if (env.contains("work_dir")) {  // reports from before the key have none
    md += fmt::format(
        "The daemon's files went to {}, where creating one cost it {:.0f} us of CPU at the "
        "sensor's rate (it creates one a frame; the file system's price, docs/deploy.md).\n\n",
        env.at("work_dir").at("path").get<std::string>(),
        env.at("work_dir").at("file_create_us_at_sensor_rate").get<double>());
  }
  if (r.at("settings").value("sensor_rate_only", false)) {
    md += "No rate search in this run (`--sensor-rate-only`).\n\n";
  } else {
    md += "| receiver | zero-loss rate (packets/s) |\n|---|---:|\n";
    md += fmt::format("| pandarcapd (config: {}) | {} |\n",
                      env.at("daemon_config").get<std::string>(),
                      rate(r.at("daemon_zero_loss_pps").get<double>()));
    if (r.contains("mcap_comparison") &&
        r.at("mcap_comparison").contains("daemon_zero_loss_pps_on")) {
      md += fmt::format("| pandarcapd, MCAP on (frames and packets) | {} |\n",
                        rate(r.at("mcap_comparison").at("daemon_zero_loss_pps_on").get<double>()));
    }
    if (r.contains("daemon_zero_loss_pps_budget_0")) {
      md += fmt::format("| pandarcapd, latency budget 0 | {} |\n",
                        rate(r.at("daemon_zero_loss_pps_budget_0").get<double>()));
    }
    md += fmt::format("| pandarcapd at <= 0.5 % loss | {} |\n",
                      rate(r.at("daemon_loss_at_most_0_5_percent_pps").get<double>()));
    md += fmt::format("| bare recvmmsg loop | {} |\n",
                      rate(r.at("bare_recvmmsg_zero_loss_pps").get<double>()));
    md += fmt::format("| recvfrom, one packet per call | {} |\n\n",
                      rate(r.at("recvfrom_zero_loss_pps").get<double>()));
    std::string limited;
    for (const auto& [who, flag] : r.at("generator_limited").items()) {
      if (flag.get<bool>()) limited += (limited.empty() ? "" : ", ") + who;
    }
    if (!limited.empty()) {
      md += "The generator could not send faster than the best passing trial for: " + limited +
            ". Those figures are lower bounds (the sender and the receivers share this machine's "
            "cores).\n\n";
    }
    md += fmt::format(
        "Daemon vs bare recvmmsg: **{:.2f}** (goal >= 0.90: {}); above recvfrom: {}.\n\n",
        r.at("daemon_vs_bare").get<double>(), yes_no(g.at("daemon_vs_bare_at_least_0_9")),
        yes_no(g.at("daemon_above_recvfrom")));
  }
  md += fmt::format("At a dual-return sensor's rate ({} packets/s), in the same run:\n\n",
                    s.at("offered_pps").get<double>());
  const double bare = s.value("bare_recvmmsg_cpu_fraction_of_one_core", 0.0);
  md +=
      "| receiver | latency budget | CPU (% of a core) | µs/packet | vs bare loop | wake-ups/s "
      "(receive, decode, writer) | frame latency p99 | receive→decoded p99 | lost | frames "
      "dropped | pcap not recorded |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  // One daemon trial's row.
  const auto row = [&](const std::string& label, const ordered_json& t) {
    const auto& w = t.at("wakeups_per_second");
    md += fmt::format(
        "| {} | {} ms | {:.2f} | {:.2f} | {:.2f}x | "
        "{:.0f}, {:.0f}, {:.0f} | {:.1f} ms | {:.2f} ms | {} | {} | {} |\n",
        label, t.at("budget_ms").dump(), 100 * t.at("cpu_fraction_of_one_core").get<double>(),
        t.at("cpu_us_per_packet").get<double>(), t.at("daemon_vs_bare_cpu").get<double>(),
        w.value("receive", 0.0), w.value("decode", 0.0), w.value("writer", 0.0),
        t.at("frame_latency_p99_ms").get<double>(), t.at("latency_p99_us").get<double>() / 1e3,
        t.at("lost").dump(), count(t, "frames_dropped"), count(t, "pcap_not_recorded"));
  };
  const std::string daemon_label =
      s.contains("receiver")
          ? fmt::format("pandarcapd ({} receiver)", s.at("receiver").get<std::string>())
          : std::string("pandarcapd");
  row(daemon_label, s);
  row(daemon_label, s.at("budget_0"));
  if (bare > 0) {
    md += fmt::format(
        "| bare recvmmsg loop (wakes per datagram, does nothing else) | - | {:.2f} | "
        "- | 1x | - | - | - | - | - | - |\n",
        100 * bare);
  }
  if (s.contains("mcap_on")) row("pandarcapd, MCAP on (frames and packets)", s.at("mcap_on"));
  for (const char* other : {"socket", "packet_ring"}) {
    if (!s.contains(other)) continue;
    const auto& t = s.at(other);
    row(fmt::format("pandarcapd ({} receiver)", other), t);
    if (t.contains("mcap_on")) {
      row(fmt::format("pandarcapd ({} receiver), MCAP on", other), t.at("mcap_on"));
    }
  }
  if (s.contains("other_receiver")) {
    const auto& o = s.at("other_receiver");
    md += fmt::format(
        "| `{}` | - | {:.2f} | {:.2f} | {} | - | - | - | {} | - | - |\n",
        o.at("command").get<std::string>(), 100 * o.at("cpu_fraction_of_one_core").get<double>(),
        o.at("cpu_us_per_packet").get<double>(),
        bare > 0 ? fmt::format("{:.2f}x", o.at("cpu_fraction_of_one_core").get<double>() / bare)
                 : std::string("-"),
        o.at("lost").dump());
  }
  md += "\n";
  if (s.contains("generator_cpu_fraction_of_one_core")) {
    // The kernel's delivery work is charged to the sender on loopback and veth (path_line()).
    const auto& k = s.at("kernel");
    const double beside_bare = s.value("bare_recvmmsg_generator_cpu_fraction_of_one_core", 0.0);
    md += fmt::format(
        "The generator (sending, and on loopback or veth the kernel's delivery) used {:.2f} % of "
        "a core beside the daemon{}; meanwhile the machine's softirq time was {:.2f} % and "
        "ksoftirqd's {:.2f} % of a core.\n\n",
        100 * s.at("generator_cpu_fraction_of_one_core").get<double>(),
        beside_bare > 0 ? fmt::format(", {:.2f} % beside the bare loop", 100 * beside_bare)
                        : std::string(),
        100 * k.at("machine_softirq_cpu_fraction_of_one_core").get<double>(),
        100 * k.at("ksoftirqd_cpu_fraction_of_one_core").get<double>());
  }
  if (r.contains("mcap_comparison")) {
    const auto& m = r.at("mcap_comparison");
    md += fmt::format(
        "MCAP on vs off (same run): CPU **{:.2f}x** ({:.2f} % -> {:.2f} % of a core); written "
        "{:.1f} -> {:.1f} MB/s ({:.1f} MB/s of MCAP); the extra CPU is {:.0f} µs per extra MB, "
        "against {:.0f} µs per MB the writer spends on PCD and pcap with MCAP off (goal <= 2x: "
        "{}); zero loss with MCAP on: {}",
        m.at("cpu_on_vs_off").get<double>(),
        100 * m.at("cpu_fraction_of_one_core_off").get<double>(),
        100 * m.at("cpu_fraction_of_one_core_on").get<double>(),
        m.at("written_mb_per_second_off").get<double>(),
        m.at("written_mb_per_second_on").get<double>(), m.at("mcap_mb_per_second").get<double>(),
        m.at("extra_cpu_us_per_extra_mb").get<double>(),
        m.at("writer_cpu_us_per_written_mb_off").get<double>(),
        yes_no(g.at("mcap_extra_cpu_per_mb_within_2x_writer_cpu_per_mb")),
        yes_no(g.at("mcap_zero_loss_at_sensor_rate")));
    if (m.contains("zero_loss_pps_on_vs_off")) {
      md += fmt::format("; zero-loss rate on/off {:.2f} (goal >= 0.90: {})",
                        m.at("zero_loss_pps_on_vs_off").get<double>(),
                        yes_no(g.at("mcap_zero_loss_rate_at_least_0_9_of_off")));
    }
    md += ".\n\n";
  }
  md += tcpdump_section(r);
  md += fmt::format(
      "- CPU with the budget: **{:.2f} %** of one core (goal <= the bare loop's: {}; <= 2 %: {})",
      100 * s.at("cpu_fraction_of_one_core").get<double>(),
      yes_no(g.at("cpu_at_sensor_rate_at_most_bare_loop")),
      yes_no(g.at("cpu_at_sensor_rate_at_most_2_percent")));
  std::string threads;
  for (const auto& [name, t] : s.at("cpu_by_thread").items()) {
    threads += fmt::format("{}{} {:.2f} % ({:.1f} µs/packet)", threads.empty() ? "" : ", ", name,
                           100 * t.at("cpu_fraction_of_one_core").get<double>(),
                           t.at("cpu_us_per_packet").get<double>());
  }
  md += ": " + threads + ".\n";
  if (s.contains("rounds") && s.at("rounds").size() > 1) {
    std::string rounds;
    for (const auto& round : s.at("rounds")) {
      rounds += fmt::format("{}{:.2f} / {:.2f} % = {:.2f}x", rounds.empty() ? "" : ", ",
                            100 * round.at("daemon_cpu_fraction_of_one_core").get<double>(),
                            100 * round.at("bare_recvmmsg_cpu_fraction_of_one_core").get<double>(),
                            round.at("daemon_vs_bare_cpu").get<double>());
    }
    md += fmt::format(
        "- Against the bare loop: **{:.2f}x**, the median of {} alternated rounds (daemon / bare "
        "loop: {}); the figures above are that round's.\n",
        s.at("daemon_vs_bare_cpu").get<double>(), s.at("rounds").size(), rounds);
  }
  md += fmt::format(
      "- Frame latency (the packet that completes a frame -> its PCD in place): p50 {:.1f} ms, "
      "**p99 {:.1f} ms** (goal <= budget + 30 ms: {}).\n",
      s.at("frame_latency_p50_ms").get<double>(), s.at("frame_latency_p99_ms").get<double>(),
      yes_no(g.at("frame_latency_p99_within_budget_plus_30_ms")));
  md += fmt::format(
      "- Receive-to-decoded latency: p50 {:.0f} µs, **p99 {:.0f} µs** (goal <= budget + 1 ms: "
      "{}), p99.9 {:.0f} µs, max {:.0f} µs.\n",
      s.at("latency_p50_us").get<double>(), s.at("latency_p99_us").get<double>(),
      yes_no(g.at("receive_to_decoded_p99_within_budget_plus_1_ms")),
      s.at("latency_p999_us").get<double>(), s.at("latency_max_us").get<double>());
  md += fmt::format("- Peak RSS: **{:.1f} MiB** (goal <= 64 MiB: {}).\n",
                    static_cast<double>(s.at("peak_rss_bytes").get<std::uint64_t>()) / (1 << 20),
                    yes_no(g.at("peak_rss_at_most_64_mib")));
  md += fmt::format(
      "- Heap allocations in the receive, decode and writer loops after warm-up: "
      "**{}** (goal 0: {}).\n\n",
      s.at("hot_path_allocations").dump(), yes_no(g.at("zero_hot_path_allocations")));
  md += cpu_budget(r);
  for (const char* who : {"daemon", "daemon_budget_0", "bare_recvmmsg", "recvfrom"}) {
    if (!r.at("trials").contains(who) || r.at("trials")[who].empty()) continue;
    md += fmt::format(
        "Trials, {}:\n\n| offered | achieved | delivered | lost | not done, by stage | CPU: "
        "generator | CPU: receiver | passed |\n|---:|---:|---:|---:|---|---:|---:|:---:|\n",
        who);
    for (const auto& t : r.at("trials")[who]) {
      md += fmt::format(
          "| {} | {} | {} | {} | {} | {} | {} | {} |\n", rate(t.at("offered_pps").get<double>()),
          rate(t.at("achieved_pps").get<double>()), rate(t.at("delivered_pps").get<double>()),
          t.at("lost").get<std::uint64_t>(), not_done(t),
          cores(t.value("generator_cpu_fraction_of_one_core", -1.0)),
          cores(t.value("cpu_fraction_of_one_core", -1.0)),
          t.value("passed", false) ? "yes" : "no");
    }
    md += "\n";
  }
  return md;
}

std::string zero_loss_svg(const ordered_json& r) {
  double lo = r.at("settings").at("min_rate").get<double>() / 1.5;
  double hi = r.at("settings").at("max_rate").get<double>() * 1.5;
  const auto& t = r.at("trials");
  std::vector<Series> delivered = {
      series(t.at("daemon"), "pandarcapd", "#1f77b4", "delivered_pps"),
      series(t.at("bare_recvmmsg"), "bare recvmmsg", "#2ca02c", "delivered_pps"),
      series(t.at("recvfrom"), "recvfrom", "#ff7f0e", "delivered_pps")};
  std::string svg =
      R"(<svg xmlns="http://www.w3.org/2000/svg" width="1000" height="440" font-family="sans-serif">)"
      "\n<rect width=\"1000\" height=\"440\" fill=\"white\"/>\n";
  const Panel left(90, 40, 370, 330, lo, hi, lo, hi, true);
  left.frame(svg, "Sent vs delivered (log-log)", "delivered packets/s");
  left.plot(svg, {"ideal", "#bbb", {{lo, lo}, {hi, hi}}}, hi / lo);
  for (const Series& s : delivered)
    left.plot(svg, s);
  legend(svg, delivered, 100);

  // Daemon loss per stage, in % of the packets sent.
  std::vector<Series> stages;
  const std::vector<std::pair<std::string, std::string>> names = {
      {"kernel_drops", "#d62728"},
      {"ring_overruns", "#9467bd"},
      {"rejected", "#8c564b"},
      {"pcap_packets_not_recorded", "#e377c2"},
      {"unaccounted", "#7f7f7f"}};
  double top = 1;
  for (const auto& [stage, colour] : names) {
    Series s{stage, colour, {}};
    for (const auto& trial : t.at("daemon")) {
      const double sent = std::max(1.0, trial.at("sent").get<double>());
      const double pct = 100 * trial.at("loss_by_stage").at(stage).get<double>() / sent;
      s.points.emplace_back(sent_rate(trial), pct);
      top = std::max(top, pct);
    }
    std::sort(s.points.begin(), s.points.end());
    stages.push_back(s);
  }
  const Panel right(600, 40, 370, 330, lo, hi, 0, top * 1.1, false);
  right.frame(svg, "pandarcapd loss per stage", "% of packets sent");
  for (const Series& s : stages)
    right.plot(svg, s);
  legend(svg, stages, 640);
  svg += "</svg>\n";
  return svg;
}

}  // namespace pandarcap::bench
