// Help for the operator who got something slightly wrong: a misspelt option named with the one
// meant, and a data port someone else holds named with who holds it.
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <string>

#include "daemon/source/udp_port_owner.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

TEST_CASE("a misspelt option is answered with the option meant", "[cli]") {
  const auto daemon = test::run_command(test::pandarcapd_command() + " --outptu-dir x 2>&1");
  CHECK(daemon.exit_code == 64);
  CHECK(daemon.out.find("unknown option '--outptu-dir' (did you mean --output-dir?)") !=
        std::string::npos);
  const auto inspect =
      test::run_command(test::binary("pandarcap-inspect").string() + " --sumary x.pcap 2>&1");
  CHECK(inspect.exit_code == 64);
  CHECK(inspect.out.find("(did you mean --summary?)") != std::string::npos);
  // Nothing near: no guess.
  const auto far = test::run_command(test::pandarcapd_command() + " --zzz 2>&1");
  CHECK(far.exit_code == 64);
  CHECK(far.out.find("unknown option '--zzz'\n") != std::string::npos);
}

TEST_CASE("/proc/net/udp is read as the kernel writes it", "[cli]") {
  const std::string text =
      "   sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  "
      "timeout inode ref pointer drops\n"
      "  123: 0100007F:0940 00000000:0000 07 00000000:00000000 00:00000000 00000000  1000"
      "        0 424242 2 0000000000000000 0\n"
      "  124: 00000000:14E9 00000000:0000 07 00000000:00000000 00:00000000 00000000     0"
      "        0 17 2 0000000000000000 0\n"
      "garbage line\n";
  const auto entries = parse_proc_net_udp(text);
  REQUIRE(entries.size() == 2);
  CHECK(entries[0].address == 0x7F000001);  // 127.0.0.1
  CHECK(entries[0].port == 2368);
  CHECK(entries[0].inode == 424242);
  CHECK(entries[1].address == 0);
  CHECK(entries[1].port == 5353);
}

TEST_CASE("a data port already held: the error names the process holding it", "[cli][daemon]") {
  // This test process holds the port.
  const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  REQUIRE(fd >= 0);
  sockaddr_in local{};
  local.sin_family = AF_INET;
  local.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::bind(fd, reinterpret_cast<const sockaddr*>(&local), sizeof local) == 0);
  socklen_t length = sizeof local;
  REQUIRE(::getsockname(fd, reinterpret_cast<sockaddr*>(&local), &length) == 0);
  const std::uint16_t port = ntohs(local.sin_port);

  const auto owner = udp_port_owner(port);
  REQUIRE(owner);
  CHECK(owner->address == 0x7F000001);
  REQUIRE(owner->pid);
  CHECK(*owner->pid == ::getpid());

  test::ScratchDir dir("port-in-use");
  const auto r = test::run_command(test::pandarcapd_command() + " --host-ip 127.0.0.1 --port " +
                                   std::to_string(port) + " --output-dir '" +
                                   (dir / "out").string() + "' 2>&1");
  ::close(fd);
  INFO(r.out);
  CHECK(r.exit_code == 1);
  CHECK(r.out.find("Address already in use. UDP port " + std::to_string(port) + " is held by pid " +
                   std::to_string(::getpid()) + " (") != std::string::npos);
  CHECK(r.out.find("another sensor.data_port (--port)") != std::string::npos);
}
