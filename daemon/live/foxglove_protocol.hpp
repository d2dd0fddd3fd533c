// Foxglove's WebSocket protocol (foxglove.websocket.v1, github.com/foxglove/ws-protocol
// docs/spec.md) as pure logic: the server's JSON messages written, the client's JSON requests
// parsed from untrusted text. No sockets here (daemon/live/foxglove_server.hpp has them); the
// fuzz target fuzz_foxglove feeds parse_client_request() arbitrary bytes.
//
// pandarcap's server is read-only: it advertises its channels and sends what a client subscribes
// to. Of the client's operations it takes "subscribe" and "unsubscribe"; everything else
// (publishing, services, parameters, assets, the connection graph) is refused with a status
// message. Plain C++17 (the server's translation unit includes it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace pandarcap::live {

inline constexpr std::string_view kSubprotocol = "foxglove.websocket.v1";

// A client's text message longer than this is refused by the WebSocket layer (close 1009), so the
// parser never sees more; a request is a few hundred bytes.
inline constexpr std::size_t kMaxClientMessageBytes = 64 * 1024;
// Subscriptions one client may hold at once (there are three channels).
inline constexpr std::size_t kMaxSubscriptions = 16;

struct Channel {
  std::uint32_t id = 0;
  std::string topic;
  std::string encoding;  // "cdr", "json"
  std::string schema_name;
  std::string schema;
  std::string schema_encoding;  // "ros2msg", "jsonschema"
};

// {"op":"serverInfo",...}: no capabilities (read-only), the session id.
std::string server_info_json(std::string_view name, std::string_view session_id);
// {"op":"advertise","channels":[...]}
std::string advertise_json(const std::vector<Channel>& channels);
// {"op":"status","level":L,"message":M}; level 0 info, 1 warning, 2 error.
std::string status_json(int level, std::string_view message);

struct ClientRequest {
  enum class Kind { kSubscribe, kUnsubscribe, kRefused, kInvalid };
  Kind kind = Kind::kInvalid;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> subscribe;  // (subscription, channel)
  std::vector<std::uint32_t> unsubscribe;                          // subscription ids
  std::string problem;  // kRefused, kInvalid: why, for the client's status message
};

// One text message from a client. Never throws; anything but a well-formed subscribe or
// unsubscribe with at most kMaxSubscriptions ids (each a uint32) is kRefused (a known operation
// this server does not offer) or kInvalid, with the reason.
ClientRequest parse_client_request(std::string_view text) noexcept;

}  // namespace pandarcap::live
