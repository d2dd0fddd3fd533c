// Which path the zero-loss harness's packets take from its generator to the receivers it measures:
// loopback (127.0.0.1, the default), a veth pair the harness makes for itself (--veth: the sender
// in a network namespace of its own, the receivers on the near end), or a real interface the user
// names (--interface, the traffic sent to --destination). The trials read the path, not the
// options: the destination the generator sends to, the address the receivers bind, the interface
// a packet_ring receiver and tcpdump watch, and the namespace the generator's sockets are made in.
//
// VethPair owns the pair and the namespace: made in its constructor, removed in its destructor,
// and also when the harness is stopped by SIGINT or SIGTERM (through the StopOnSignal it is given).
#pragma once

#include <string>
#include <vector>

#include "bench/stop_on_signal.hpp"

namespace pandarcap::bench {

struct TrafficPath {
  std::string kind = "loopback";         // "loopback" | "veth" | "interface"
  std::string interface = "lo";          // where the packets arrive
  std::string receive_ip = "127.0.0.1";  // the daemon's --host-ip, the reference receivers' bind
  std::string destination_ip = "127.0.0.1";  // where the generator sends
  std::string sender_namespace;  // "": the harness's own; else /run/netns/NAME for the generator
  // Where the kernel's delivery work lands, as measured (bench/README.md), for the report.
  std::string delivery_note() const;
};

class VethPair {
 public:
  // Makes the pair: `pcb<pid>n` (near, 10.231.X.1/30, up) in this namespace, `pcb<pid>f`
  // (10.231.X.2/30, up) in namespace `pandarcap-bench-<pid>` (its lo up too), with permanent
  // neighbour entries both ways so that no trial starts by waiting on ARP. X is taken from the
  // PID. Throws std::runtime_error (with the ip command's output) when a step fails, after
  // removing what it made. `stop` removes them too when a signal stops the harness; it must
  // outlive the pair.
  explicit VethPair(StopOnSignal& stop);
  ~VethPair();
  VethPair(const VethPair&) = delete;
  VethPair& operator=(const VethPair&) = delete;

  TrafficPath path() const;
  const std::string& near_name() const { return near_; }
  const std::string& namespace_name() const { return namespace_; }

 private:
  void remove() noexcept;
  std::string near_, far_, namespace_, near_ip_, far_ip_;
  StopOnSignal* stop_ = nullptr;  // its guard removes them
  int guard_ = -1;
};

}  // namespace pandarcap::bench
