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

}  // namespace pandarcap
