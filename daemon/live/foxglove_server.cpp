#include "daemon/live/foxglove_server.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <vector>
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include "daemon/live/foxglove_protocol.hpp"

namespace pandarcap::live {
namespace {

using Server = websocketpp::server<websocketpp::config::asio>;
using Hdl = websocketpp::connection_hdl;
using Opcode = websocketpp::frame::opcode::value;

constexpr std::uint32_t kPointsChannelId = 1, kHealthChannelId = 2, kStatusChannelId = 3;
// How often the thread looks for what the writer handed over: a frame waits at most this long.
constexpr auto kPollInterval = std::chrono::milliseconds(10);
constexpr long kHandshakeTimeoutMs = 5000;
constexpr const char* kStatusSchema =
    R"js({"type":"object","title":"the sensor's status over PTC, the health record's sensor_status"})js";

void put_u32(std::uint8_t* at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i)
    at[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

}  // namespace

struct FoxgloveServer::Impl {
  struct Client {
    std::string remote;
    std::map<std::uint32_t, std::uint32_t> subscriptions;  // subscription id -> channel id
  };

  Impl(const LiveOptions& o, LiveHandover& h) : options(o), handover(h) {}

  void set_up();
  // Binds and listens; false (counted, the errno kept) when the port cannot be bound.
  bool try_listen();
  void poll();
  bool validate(Hdl hdl);
  void opened(Hdl hdl);
  void closed(Hdl hdl, const char* how);
  void received(Hdl hdl, const Server::message_ptr& message);
  void subscribed(Client& client);
  // Sends `bytes` to one client unless its queue would overfill (then counted as dropped).
  void send_data(Hdl hdl, const std::vector<std::uint8_t>& bytes);
  void send_text(Hdl hdl, const std::string& text);
  // `message` (a Message Data with room for the subscription id) to every subscription of
  // `channel`.
  void broadcast(std::uint32_t channel, std::vector<std::uint8_t>& message);
  void publish_health(const std::vector<std::uint8_t>& slot);
  void count_clients();

  LiveOptions options;
  LiveHandover& handover;
  Server server;
  std::unique_ptr<asio::steady_timer> timer;            // after `server`: destroyed first
  std::map<Hdl, Client, std::owner_less<Hdl>> clients;  // validated, not yet closed
  std::string info, advertise;
  std::vector<std::uint8_t> health_message, status_message;  // this thread's, reused
  std::uint16_t port = 0;
  asio::ip::address_v4 address;
  std::chrono::steady_clock::time_point next_listen_attempt;
  std::string last_listen_error;  // logged once until it changes or the port is bound
};

void FoxgloveServer::Impl::set_up() {
  server.clear_access_channels(websocketpp::log::alevel::all);
  server.clear_error_channels(websocketpp::log::elevel::all);
  server.init_asio();
  server.set_reuse_addr(true);
  server.set_max_message_size(kMaxClientMessageBytes);
  server.set_max_http_body_size(kMaxClientMessageBytes);
  server.set_open_handshake_timeout(kHandshakeTimeoutMs);
  server.set_validate_handler([this](Hdl hdl) { return validate(hdl); });
  server.set_open_handler([this](Hdl hdl) { opened(hdl); });
  server.set_close_handler([this](Hdl hdl) { closed(hdl, "disconnected"); });
  server.set_fail_handler([this](Hdl hdl) { closed(hdl, "failed"); });
  server.set_message_handler(
      [this](Hdl hdl, const Server::message_ptr& message) { received(hdl, message); });
  asio::error_code ec;
  address = asio::ip::make_address_v4(options.address, ec);
  if (ec)
    throw std::runtime_error(fmt::format("live.address {}: {}", options.address, ec.message()));
  handover.counters.port.store(options.port, std::memory_order_relaxed);
  handover.counters.listen_retry_ms.store(options.listen_retry_ms, std::memory_order_relaxed);
  info = server_info_json(
      options.name, fmt::format("{}", std::chrono::system_clock::now().time_since_epoch().count()));
  advertise = advertise_json({
      {kPointsChannelId, options.points_topic, "cdr", options.points_schema_name,
       options.points_schema, "ros2msg"},
      {kHealthChannelId, options.health_topic, "json", "pandarcap.Health", options.health_schema,
       "jsonschema"},
      {kStatusChannelId, options.status_topic, "json", "pandarcap.SensorStatus", kStatusSchema,
       "jsonschema"},
  });
  timer = std::make_unique<asio::steady_timer>(server.get_io_service());
  // The first attempt is the constructor's, not the poll's.
  next_listen_attempt = std::chrono::steady_clock::time_point::max();
  poll();
}

bool FoxgloveServer::Impl::try_listen() {
  LiveCounters& counters = handover.counters;
  websocketpp::lib::error_code error;
  server.listen(asio::ip::tcp::endpoint(address, options.port), error);
  if (!error) server.start_accept(error);
  if (error) {
    // websocketpp hands asio's error through: errno's value in asio's system category.
    const std::string_view category = error.category().name();
    const bool system = category == "asio.system" || category == "system" || category == "generic";
    counters.listen_errno.store(system ? error.value() : EIO, std::memory_order_relaxed);
    websocketpp::lib::error_code ignored;
    if (server.is_listening()) server.stop_listening(ignored);  // listening, but not accepting
    next_listen_attempt =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(options.listen_retry_ms);
    const std::string message = error.message();
    if (message != last_listen_error) {
      // The capture goes on; the health says degraded, naming the port, until it is bound.
      spdlog::warn(
          "live view: cannot listen on {}:{}: {}; the capture goes on without it, trying again "
          "every {:g} s",
          options.address, options.port, message, options.listen_retry_ms / 1000.0);
      last_listen_error = message;
    }
    return false;
  }
  asio::error_code ec;
  port = server.get_local_endpoint(ec).port();
  counters.port.store(port, std::memory_order_relaxed);
  counters.listen_errno.store(0, std::memory_order_relaxed);
  counters.listening.store(true, std::memory_order_relaxed);
  if (!last_listen_error.empty()) {
    spdlog::info("live view: port {} is free now: listening", port);
    last_listen_error.clear();
  }
  return true;
}

bool FoxgloveServer::Impl::validate(Hdl hdl) {
  const Server::connection_ptr con = server.get_con_from_hdl(hdl);
  if (clients.size() >= options.max_clients) {
    con->set_status(websocketpp::http::status_code::service_unavailable);
    spdlog::warn("live view: {} refused: {} viewers connected already (live.max_clients)",
                 con->get_remote_endpoint(), clients.size());
    return false;
  }
  const std::vector<std::string>& asked = con->get_requested_subprotocols();
  if (std::find(asked.begin(), asked.end(), kSubprotocol) == asked.end()) {
    con->set_status(websocketpp::http::status_code::bad_request);
    return false;
  }
  con->select_subprotocol(std::string(kSubprotocol));
  clients.emplace(hdl, Client{con->get_remote_endpoint(), {}});
  count_clients();
  return true;
}

void FoxgloveServer::Impl::opened(Hdl hdl) {
  const auto it = clients.find(hdl);
  if (it == clients.end()) return;
  spdlog::info("live view: {} connected ({} of {})", it->second.remote, clients.size(),
               options.max_clients);
  send_text(hdl, info);
  send_text(hdl, advertise);
}

void FoxgloveServer::Impl::closed(Hdl hdl, const char* how) {
  const auto it = clients.find(hdl);
  if (it == clients.end()) return;
  spdlog::info("live view: {} {}", it->second.remote, how);
  clients.erase(it);
  count_clients();
}

void FoxgloveServer::Impl::count_clients() {
  std::uint64_t points = 0;
  for (const auto& [hdl, client] : clients) {
    for (const auto& [id, channel] : client.subscriptions) {
      if (channel == kPointsChannelId) {
        ++points;
        break;
      }
    }
  }
  handover.counters.clients.store(clients.size(), std::memory_order_relaxed);
  handover.counters.points_subscribers.store(points, std::memory_order_relaxed);
}

void FoxgloveServer::Impl::received(Hdl hdl, const Server::message_ptr& message) {
  const auto it = clients.find(hdl);
  if (it == clients.end()) return;
  Client& client = it->second;
  if (message->get_opcode() != websocketpp::frame::opcode::text) {
    send_text(hdl, status_json(2, "binary client messages refused: this server is read-only"));
    return;
  }
  const ClientRequest request = parse_client_request(message->get_payload());
  switch (request.kind) {
    case ClientRequest::Kind::kSubscribe:
      for (const auto& [id, channel] : request.subscribe) {
        if (channel < kPointsChannelId || channel > kStatusChannelId) {
          send_text(hdl, status_json(2, fmt::format("no channel {}", channel)));
        } else if (client.subscriptions.count(id) == 0 &&
                   client.subscriptions.size() >= kMaxSubscriptions) {
          send_text(hdl, status_json(2, "too many subscriptions"));
        } else {
          client.subscriptions[id] = channel;
        }
      }
      count_clients();
      break;
    case ClientRequest::Kind::kUnsubscribe:
      for (const std::uint32_t id : request.unsubscribe)
        client.subscriptions.erase(id);
      count_clients();
      break;
    case ClientRequest::Kind::kRefused:
    case ClientRequest::Kind::kInvalid:
      send_text(hdl, status_json(2, request.problem));
      break;
  }
}

void FoxgloveServer::Impl::send_text(Hdl hdl, const std::string& text) {
  websocketpp::lib::error_code ec;
  const Server::connection_ptr con = server.get_con_from_hdl(hdl, ec);
  if (ec || con->get_state() != websocketpp::session::state::open) return;
  // Replies are small, but a client that floods requests without reading gets none past its
  // queue's bound.
  if (con->get_buffered_amount() + text.size() > options.client_queue_bytes) return;
  con->send(text, websocketpp::frame::opcode::text);
}

void FoxgloveServer::Impl::send_data(Hdl hdl, const std::vector<std::uint8_t>& bytes) {
  websocketpp::lib::error_code ec;
  const Server::connection_ptr con = server.get_con_from_hdl(hdl, ec);
  if (ec || con->get_state() != websocketpp::session::state::open) return;
  LiveCounters& counters = handover.counters;
  if (con->get_buffered_amount() + bytes.size() > options.client_queue_bytes) {
    counters.messages_dropped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  ec = con->send(bytes.data(), bytes.size(), websocketpp::frame::opcode::binary);
  (ec ? counters.messages_dropped : counters.messages_sent).fetch_add(1, std::memory_order_relaxed);
}

void FoxgloveServer::Impl::broadcast(std::uint32_t channel, std::vector<std::uint8_t>& message) {
  for (const auto& [hdl, client] : clients) {
    for (const auto& [id, subscribed] : client.subscriptions) {
      if (subscribed != channel) continue;
      put_u32(message.data() + kSubscriptionIdOffset, id);
      send_data(hdl, message);  // copied into the connection's queue
    }
  }
}

void FoxgloveServer::Impl::publish_health(const std::vector<std::uint8_t>& slot) {
  if (slot.size() < 8) return;
  const auto* time = slot.data();
  const std::string_view json(reinterpret_cast<const char*>(slot.data() + 8), slot.size() - 8);
  const auto fill = [&](std::vector<std::uint8_t>& out, std::string_view payload) {
    out.assign(kMessageDataHeaderBytes, 0);
    out[0] = kMessageDataOpcode;
    std::memcpy(out.data() + 5, time, 8);
    out.insert(out.end(), payload.begin(), payload.end());
  };
  fill(health_message, json);
  broadcast(kHealthChannelId, health_message);
  // The record is the writer's own rendering: it parses.
  const nlohmann::json record = nlohmann::json::parse(json, nullptr, false);
  if (record.is_object() && record.contains("sensor_status")) {
    fill(status_message, record.at("sensor_status").dump());
    broadcast(kStatusChannelId, status_message);
  }
}

void FoxgloveServer::Impl::poll() {
  if (std::vector<std::uint8_t>* points = handover.points.take()) {
    broadcast(kPointsChannelId, *points);
  }
  if (const std::vector<std::uint8_t>* health = handover.health.take()) publish_health(*health);
  if (!handover.counters.listening.load(std::memory_order_relaxed) &&
      std::chrono::steady_clock::now() >= next_listen_attempt) {
    try_listen();
  }
  timer->expires_after(kPollInterval);
  timer->async_wait([this](const asio::error_code& ec) {
    if (!ec) poll();
  });
}

FoxgloveServer::FoxgloveServer(const LiveOptions& options, LiveHandover& handover)
    : impl_(std::make_unique<Impl>(options, handover)) {
  impl_->set_up();
  if (!impl_->try_listen()) return;  // poll() tries again
  if (options.address != "127.0.0.1") {
    spdlog::warn(
        "live view: listening on {}:{}, not 127.0.0.1: anyone who reaches it sees the sensor "
        "(no authentication, no encryption); prefer ssh -L",
        options.address, impl_->port);
  } else {
    spdlog::info("live view: Foxglove WebSocket on ws://127.0.0.1:{}", impl_->port);
  }
}

FoxgloveServer::~FoxgloveServer() = default;

std::uint16_t FoxgloveServer::port() const noexcept {
  return impl_->port;
}

void FoxgloveServer::run() {
  try {
    impl_->server.run();
  } catch (const std::exception& error) {
    // The capture goes on without its viewers.
    spdlog::error("live view stopped: {}", error.what());
  }
}

void FoxgloveServer::stop() noexcept {
  impl_->server.stop();
}

}  // namespace pandarcap::live
