// IPv4 addresses as the configuration, the command lines and the sensor write them ("a.b.c.d").
//
// The one parser: the configuration checks addresses with it, the daemon's sockets and the
// replay's sensor filter take their addresses from it, the benchmark's traffic generator too, so
// an address one of them accepts the others accept. Pure (no socket is touched).
#pragma once

#include <netinet/in.h>

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace pandarcap {

// The address in network byte order, or nothing when `text` is not exactly four decimal octets
// (inet_pton's rules: no shorthand such as "127.1", no leading or trailing space).
std::optional<in_addr> parse_ipv4(const std::string& text) noexcept;

// The same in host byte order (what the pcap headers and the source filters compare).
std::optional<std::uint32_t> parse_ipv4_host_order(const std::string& text) noexcept;

// The address; throws std::invalid_argument("WHAT 'TEXT' is not an IPv4 address") when it does
// not parse: `what` names the setting ("host_ip").
in_addr require_ipv4(const std::string& text, const char* what);

// The address with `port` as a socket address; throws std::invalid_argument("WHAT 'TEXT' is not
// an IPv4 address") when it does not parse: `what` names the setting ("host_ip").
sockaddr_in ipv4_endpoint(const std::string& text, std::uint16_t port, const char* what);

// An IPv4 source (address in host byte order, and port) packed into one integer, so a thread
// can hand it to another through an atomic: 0 is "none".
constexpr std::uint64_t pack_ipv4_source(std::uint32_t ip, std::uint16_t port) noexcept {
  return (std::uint64_t{1} << 48) | (std::uint64_t{ip} << 16) | port;
}
constexpr std::uint32_t packed_ipv4(std::uint64_t source) noexcept {
  return static_cast<std::uint32_t>(source >> 16);
}
constexpr std::uint16_t packed_port(std::uint64_t source) noexcept {
  return static_cast<std::uint16_t>(source);
}
// Appends "192.168.1.201:2368" (a packed source; "none" for 0). Allocates nothing once `out`
// has room for 21 more characters.
void append_ipv4_source(std::string& out, std::uint64_t source);
// The same as a JSON value: the source in quotes, or null for none.
void append_ipv4_source_json(std::string& out, std::uint64_t source);

}  // namespace pandarcap
