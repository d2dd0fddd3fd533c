#include "bench/traffic_path.hpp"

#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <filesystem>
#include <stdexcept>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/stop_on_signal.hpp"

namespace pandarcap::bench {

namespace {

std::string ip_program() {
  for (const char* p : {"/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip"}) {
    if (std::filesystem::exists(p)) return p;
  }
  throw std::runtime_error(
      "--veth needs the ip command (iproute2), found in none of /usr/sbin, "
      "/sbin, /usr/bin, /bin");
}

// `ip ARGS...`; throws with its output when it fails.
void ip(const std::string& program, const std::string& args) {
  const harness::ShellResult result = harness::run_shell(program + " " + args + " 2>&1");
  if (result.status != 0) {
    throw std::runtime_error(fmt::format("'ip {}' failed: {}", args, result.out));
  }
}

}  // namespace

std::string TrafficPath::delivery_note() const {
  if (kind == "veth") {
    return "veth: the sender's transmit puts each datagram on the near end's backlog (netif_rx) "
           "and the kernel delivers it (IP, UDP, the socket's queue or the packet ring) in a "
           "NET_RX softirq on the sending CPU as the send returns (measured: one per datagram, "
           "on the sender's CPU), so it is charged to the generator's thread, as on loopback; "
           "the receivers pay only for reading.";
  }
  if (kind == "interface") {
    return "a real interface: the kernel's delivery work runs in the NIC's receive softirq (NAPI) "
           "on the CPU its interrupt lands on, charged to whatever runs there or to ksoftirqd, "
           "not to the generator.";
  }
  return "loopback: the kernel's delivery work (a NET_RX softirq per datagram: IP, UDP, the "
         "socket's queue) runs on the sending CPU as the send returns, so it is charged to the "
         "generator's thread; the receivers pay only for reading.";
}

VethPair::VethPair(StopOnSignal& stop) {
  const int pid = static_cast<int>(::getpid());
  // A /30 of 10.231.0.0/16 from the PID: 16384 of them, .1 near and .2 far.
  const int index = pid % 16384;
  const std::string base = fmt::format("10.231.{}.", index / 64);
  const int host = (index % 64) * 4;
  near_ = fmt::format("pcb{}n", pid);
  far_ = fmt::format("pcb{}f", pid);
  namespace_ = fmt::format("pandarcap-bench-{}", pid);
  near_ip_ = base + std::to_string(host + 1);
  far_ip_ = base + std::to_string(host + 2);
  // Locally administered MACs from the PID, so the neighbour entries can be written at once.
  const auto mac = [&](int end) {
    return fmt::format("02:70:{:02x}:{:02x}:{:02x}:{:02x}", (pid >> 24) & 0xff, (pid >> 16) & 0xff,
                       (pid >> 8) & 0xff, ((pid & 0x7f) << 1) | end);
  };
  const std::string program = ip_program();

  // Removed at the end, after a failure, and when a signal stops the harness, by the guard.
  guard_ = stop.guard({{program, "link", "del", near_}, {program, "netns", "del", namespace_}});
  stop_ = &stop;
  // A signal waits until the pair is whole (or removed after a failure): the handler removes
  // what the steps made, and cannot know what a step still running would make after it.
  const StopOnSignal::Held held;
  try {
    ip(program, "netns add " + namespace_);
    ip(program, fmt::format("link add {} address {} type veth peer name {} address {}", near_,
                            mac(0), far_, mac(1)));
    ip(program, fmt::format("link set {} netns {}", far_, namespace_));
    ip(program, fmt::format("addr add {}/30 dev {}", near_ip_, near_));
    ip(program, fmt::format("link set {} up", near_));
    ip(program, fmt::format("-n {} addr add {}/30 dev {}", namespace_, far_ip_, far_));
    ip(program, fmt::format("-n {} link set {} up", namespace_, far_));
    ip(program, fmt::format("-n {} link set lo up", namespace_));
    ip(program, fmt::format("-n {} neigh replace {} lladdr {} dev {} nud permanent", namespace_,
                            near_ip_, mac(0), far_));
    ip(program,
       fmt::format("neigh replace {} lladdr {} dev {} nud permanent", far_ip_, mac(1), near_));
  } catch (...) {
    remove();
    throw;
  }
}

VethPair::~VethPair() {
  remove();
}

void VethPair::remove() noexcept {
  // Deleting one end deletes both; the namespace goes with its name once no socket holds it.
  stop_->run_guarded_now(guard_);
}

TrafficPath VethPair::path() const {
  TrafficPath p;
  p.kind = "veth";
  p.interface = near_;
  p.receive_ip = near_ip_;
  p.destination_ip = near_ip_;
  p.sender_namespace = "/run/netns/" + namespace_;
  return p;
}

}  // namespace pandarcap::bench
