#include "daemon/live/foxglove_protocol.hpp"

#include <fmt/format.h>

#include <array>
#include <nlohmann/json.hpp>

namespace pandarcap::live {
namespace {

using nlohmann::json;

// The client operations of the specification this server does not offer.
constexpr std::array<std::string_view, 11> kRefusedOps = {"advertise",
                                                          "unadvertise",
                                                          "getParameters",
                                                          "setParameters",
                                                          "subscribeParameterUpdates",
                                                          "unsubscribeParameterUpdates",
                                                          "callService",
                                                          "fetchAsset",
                                                          "subscribeConnectionGraph",
                                                          "unsubscribeConnectionGraph",
                                                          "subscribeServices"};

// A uint32 from a JSON value, or nothing.
bool as_u32(const json& v, std::uint32_t& out) {
  if (!v.is_number_unsigned()) return false;
  const auto n = v.get<std::uint64_t>();
  if (n > 0xFFFF'FFFFu) return false;
  out = static_cast<std::uint32_t>(n);
  return true;
}

ClientRequest invalid(std::string problem) {
  ClientRequest r;
  r.kind = ClientRequest::Kind::kInvalid;
  r.problem = std::move(problem);
  return r;
}

ClientRequest parse(std::string_view text) {
  // Depth is bounded by the message size (kMaxClientMessageBytes); nlohmann's parser recurses per
  // level, so deeper than a request can be is refused before parsing.
  int depth = 0;
  for (const char c : text) {
    if (c == '[' || c == '{') ++depth;
    if (depth > 8) return invalid("nested too deeply");
    if (c == ']' || c == '}') --depth;
  }
  const json j = json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return invalid("not a JSON object");
  const auto op_it = j.find("op");
  if (op_it == j.end() || !op_it->is_string()) return invalid("no \"op\"");
  const std::string& op = op_it->get_ref<const std::string&>();
  ClientRequest r;
  if (op == "subscribe") {
    const auto subs = j.find("subscriptions");
    if (subs == j.end() || !subs->is_array()) return invalid("subscribe without \"subscriptions\"");
    if (subs->size() > kMaxSubscriptions) return invalid("too many subscriptions");
    for (const json& s : *subs) {
      std::uint32_t id = 0, channel = 0;
      if (!s.is_object() || !s.contains("id") || !s.contains("channelId") ||
          !as_u32(s.at("id"), id) || !as_u32(s.at("channelId"), channel)) {
        return invalid("a subscription needs \"id\" and \"channelId\" (uint32)");
      }
      r.subscribe.emplace_back(id, channel);
    }
    r.kind = ClientRequest::Kind::kSubscribe;
    return r;
  }
  if (op == "unsubscribe") {
    const auto ids = j.find("subscriptionIds");
    if (ids == j.end() || !ids->is_array()) {
      return invalid("unsubscribe without \"subscriptionIds\"");
    }
    if (ids->size() > kMaxSubscriptions) return invalid("too many subscription ids");
    for (const json& v : *ids) {
      std::uint32_t id = 0;
      if (!as_u32(v, id)) return invalid("a subscription id is a uint32");
      r.unsubscribe.push_back(id);
    }
    r.kind = ClientRequest::Kind::kUnsubscribe;
    return r;
  }
  for (const std::string_view refused : kRefusedOps) {
    if (op == refused) {
      r.kind = ClientRequest::Kind::kRefused;
      r.problem = fmt::format("\"{}\" refused: this server is read-only", refused);
      return r;
    }
  }
  return invalid("unknown op");
}

}  // namespace

std::string server_info_json(std::string_view name, std::string_view session_id) {
  return json{{"op", "serverInfo"},
              {"name", name},
              {"capabilities", json::array()},
              {"supportedEncodings", json::array()},
              {"metadata", json::object()},
              {"sessionId", session_id}}
      .dump();
}

std::string advertise_json(const std::vector<Channel>& channels) {
  json list = json::array();
  for (const Channel& c : channels) {
    list.push_back({{"id", c.id},
                    {"topic", c.topic},
                    {"encoding", c.encoding},
                    {"schemaName", c.schema_name},
                    {"schema", c.schema},
                    {"schemaEncoding", c.schema_encoding}});
  }
  return json{{"op", "advertise"}, {"channels", list}}.dump();
}

std::string status_json(int level, std::string_view message) {
  return json{{"op", "status"}, {"level", level}, {"message", message}}.dump(
      -1, ' ', false, json::error_handler_t::replace);
}

ClientRequest parse_client_request(std::string_view text) noexcept {
  try {
    return parse(text);
  } catch (const std::exception&) {
    // nlohmann's accessors on a value of the wrong type, or memory: refused, never thrown.
    return invalid("malformed request");
  }
}

}  // namespace pandarcap::live
