// Fuzz target: a live viewer's text messages (daemon/live/foxglove_protocol.hpp), the only client
// input pandarcap parses itself (the WebSocket handshake and framing are websocketpp's, bounded by
// its HTTP parser and live's message-size limit). The input is one message, as the server hands
// it to parse_client_request().
//
// Invariants, beyond "no crash, no UB":
//   - a subscribe holds 1..kMaxSubscriptions (id, channel) pairs, an unsubscribe at most
//     kMaxSubscriptions ids, and neither a problem;
//   - a refused or invalid request says why, and the status message saying so to the client is
//     JSON that parses back to the same text.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <string_view>

#include "daemon/live/foxglove_protocol.hpp"

using pandarcap::live::ClientRequest;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > pandarcap::live::kMaxClientMessageBytes) return 0;  // refused before parsing
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const ClientRequest r = pandarcap::live::parse_client_request(text);
  switch (r.kind) {
    case ClientRequest::Kind::kSubscribe:
      if (r.subscribe.size() > pandarcap::live::kMaxSubscriptions) std::abort();
      if (!r.problem.empty() || !r.unsubscribe.empty()) std::abort();
      break;
    case ClientRequest::Kind::kUnsubscribe:
      if (r.unsubscribe.size() > pandarcap::live::kMaxSubscriptions) std::abort();
      if (!r.problem.empty() || !r.subscribe.empty()) std::abort();
      break;
    case ClientRequest::Kind::kRefused:
    case ClientRequest::Kind::kInvalid: {
      if (r.problem.empty()) std::abort();
      const auto status = nlohmann::json::parse(pandarcap::live::status_json(2, r.problem));
      if (status.at("message").get<std::string>() != r.problem) std::abort();
      break;
    }
  }
  return 0;
}
