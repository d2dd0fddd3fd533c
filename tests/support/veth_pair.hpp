// A veth pair made by a test (as root): the near end in the test's own network namespace, the
// far end in a namespace of its own, where a "sensor" sends from. Both are removed when the
// pair goes out of scope. The packet_ring receiver reads the near end as it would a NIC.
//
//   near  <name>n  10.<a>.<b>.1/29         far  <name>f  10.<a>.<b>.2/29 (and .3, a second
//                                                host on the same segment)
//
// FarNamespace enters the far namespace on the calling thread only (setns): sockets created
// meanwhile belong to it, and keep sending from there after it is left.
#pragma once

#include <fcntl.h>
#include <sched.h>
#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <stdexcept>
#include <string>

#include "support/loop_file_system.hpp"
#include "support/test_support.hpp"

namespace pandarcap::test {

class VethPair {
 public:
  // `tag`: a few letters, unique among the tests that run at once (the PID is added).
  explicit VethPair(const std::string& tag) {
    const std::string id = tag + std::to_string(::getpid() % 100000);
    ns_ = "pc" + id;
    near_ = id + "n";
    far_ = id + "f";
    const unsigned pid = static_cast<unsigned>(::getpid());
    const std::string net = "10." + std::to_string(100 + pid % 100) + "." +
                            std::to_string(pid / 100 % 250) + "." + std::to_string(tag.size() * 8);
    const auto host = [&](int n) {
      return net.substr(0, net.rfind('.') + 1) + std::to_string(tag.size() * 8 + n);
    };
    near_ip_ = host(1);
    far_ip_ = host(2);
    second_far_ip_ = host(3);
    ok_ = shell("ip netns add " + ns_) && make_link();
  }
  // The pair made again after a test removed it (the same names and addresses; new indexes).
  bool make_link() {
    const std::string ns = " -n " + ns_ + " ";
    bool ok = shell("ip link add " + near_ + " type veth peer name " + far_ + " netns " + ns_) &&
              shell("ip addr add " + near_ip_ + "/29 dev " + near_) &&
              shell("ip link set " + near_ + " up") &&
              shell("ip" + ns + "addr add " + far_ip_ + "/29 dev " + far_) &&
              shell("ip" + ns + "addr add " + second_far_ip_ + "/29 dev " + far_) &&
              shell("ip" + ns + "link set " + far_ + " up") && shell("ip" + ns + "link set lo up");
    if (ok) {
      // Neighbours known up front: no first datagram waits for ARP.
      ok = shell("ip" + ns + "neigh replace " + near_ip_ + " lladdr " + mac(near_, "") + " dev " +
                 far_ + " nud permanent") &&
           shell("ip neigh replace " + far_ip_ + " lladdr " + mac(far_, ns_) + " dev " + near_ +
                 " nud permanent") &&
           shell("ip neigh replace " + second_far_ip_ + " lladdr " + mac(far_, ns_) + " dev " +
                 near_ + " nud permanent");
    }
    return ok;
  }
  ~VethPair() {
    shell("ip link del " + near_ + " 2>/dev/null");
    shell("ip netns del " + ns_ + " 2>/dev/null");
  }
  VethPair(const VethPair&) = delete;
  VethPair& operator=(const VethPair&) = delete;

  bool ok() const { return ok_; }
  const std::string& ns() const { return ns_; }
  const std::string& near() const { return near_; }
  const std::string& far() const { return far_; }
  const std::string& near_ip() const { return near_ip_; }
  const std::string& far_ip() const { return far_ip_; }
  const std::string& second_far_ip() const { return second_far_ip_; }
  std::string near_mac() const { return mac(near_, ""); }
  std::string far_mac() const { return mac(far_, ns_); }

 private:
  static std::string mac(const std::string& link, const std::string& ns) {
    const std::string in = ns.empty() ? "" : "ip netns exec " + ns + " ";
    std::string out = run_command(in + "cat /sys/class/net/" + link + "/address").out;
    while (!out.empty() && (out.back() == '\n' || out.back() == ' '))
      out.pop_back();
    return out;
  }
  std::string ns_, near_, far_, near_ip_, far_ip_, second_far_ip_;
  bool ok_ = false;
};

// While it lives, the calling thread is in `ns` (sockets it creates are that namespace's).
class FarNamespace {
 public:
  explicit FarNamespace(const std::string& ns)
      : home_(::open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC)) {
    const int far = ::open(("/run/netns/" + ns).c_str(), O_RDONLY | O_CLOEXEC);
    if (home_ < 0 || far < 0 || ::setns(far, CLONE_NEWNET) != 0) {
      if (far >= 0) ::close(far);
      throw std::runtime_error("cannot enter network namespace " + ns);
    }
    ::close(far);
  }
  ~FarNamespace() {
    ::setns(home_, CLONE_NEWNET);
    ::close(home_);
  }
  FarNamespace(const FarNamespace&) = delete;
  FarNamespace& operator=(const FarNamespace&) = delete;

 private:
  int home_;
};

}  // namespace pandarcap::test
