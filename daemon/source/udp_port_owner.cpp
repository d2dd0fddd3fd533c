#include "daemon/source/udp_port_owner.hpp"

#include <dirent.h>
#include <fmt/format.h>
#include <unistd.h>

#include <charconv>
#include <sstream>

#include "daemon/io/text_file.hpp"

namespace pandarcap {

namespace {

template <typename T>
bool parse_hex(std::string_view text, T& out) {
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), out, 16);
  return error == std::errc() && end == text.data() + text.size();
}

}  // namespace

std::vector<UdpSocketEntry> parse_proc_net_udp(std::string_view text) {
  // "  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout
  // inode ..." then one line a socket: "0: 0100007F:0940 00000000:0000 07 ... 1000 0 12345 ..."
  std::vector<UdpSocketEntry> entries;
  std::istringstream lines{std::string(text)};
  std::string line;
  std::getline(lines, line);  // the header
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    std::string slot, local, remote, state, queues, timer, retransmits, uid, timeout, inode;
    if (!(words >> slot >> local >> remote >> state >> queues >> timer >> retransmits >> uid >>
          timeout >> inode))
      continue;
    const auto colon = local.find(':');
    UdpSocketEntry e;
    std::uint32_t address_le = 0;  // the kernel prints the address as a number in host order
    if (colon == std::string::npos ||
        !parse_hex(std::string_view(local).substr(0, colon), address_le) ||
        !parse_hex(std::string_view(local).substr(colon + 1), e.port)) {
      continue;
    }
    // /proc prints the network-order bytes as a little-endian number: 0100007F is 127.0.0.1.
    e.address = ((address_le & 0xFF) << 24) | ((address_le & 0xFF00) << 8) |
                ((address_le >> 8) & 0xFF00) | (address_le >> 24);
    const auto [end, error] = std::from_chars(inode.data(), inode.data() + inode.size(), e.inode);
    if (error != std::errc() || end != inode.data() + inode.size()) continue;
    entries.push_back(e);
  }
  return entries;
}

std::optional<PortOwner> udp_port_owner(std::uint16_t port) {
  std::optional<UdpSocketEntry> held;
  // One line of ~130 bytes a socket: 16 MiB is over 100 000 sockets.
  const TextFile table = read_text_file("/proc/net/udp", 16u << 20);
  for (const UdpSocketEntry& e : parse_proc_net_udp(table.text)) {
    if (e.port == port) {
      held = e;
      break;
    }
  }
  if (!held) return std::nullopt;
  PortOwner owner;
  owner.address = held->address;
  const std::string target = fmt::format("socket:[{}]", held->inode);
  DIR* proc = ::opendir("/proc");
  if (proc == nullptr) return owner;
  while (const dirent* process = ::readdir(proc)) {
    int pid = 0;
    const std::string_view name = process->d_name;
    const auto [end, error] = std::from_chars(name.data(), name.data() + name.size(), pid);
    if (error != std::errc() || end != name.data() + name.size()) continue;
    const std::string fd_dir = fmt::format("/proc/{}/fd", pid);
    DIR* fds = ::opendir(fd_dir.c_str());
    if (fds == nullptr) continue;  // another user's process: not ours to look into
    bool found = false;
    while (const dirent* fd = ::readdir(fds)) {
      char link[64];
      const std::string path = fd_dir + "/" + fd->d_name;
      const ssize_t n = ::readlink(path.c_str(), link, sizeof link);
      if (n > 0 && std::string_view(link, static_cast<std::size_t>(n)) == target) {
        found = true;
        break;
      }
    }
    ::closedir(fds);
    if (found) {
      owner.pid = pid;
      owner.command = read_text_file(fmt::format("/proc/{}/comm", pid)).text;
      while (!owner.command.empty() && owner.command.back() == '\n')
        owner.command.pop_back();
      break;
    }
  }
  ::closedir(proc);
  return owner;
}

std::string port_in_use_hint(std::uint16_t port) {
  const auto owner = udp_port_owner(port);
  if (!owner) return "";
  const std::uint32_t a = owner->address;
  const std::string address =
      fmt::format("{}.{}.{}.{}", a >> 24, (a >> 16) & 0xFF, (a >> 8) & 0xFF, a & 0xFF);
  if (owner->pid) {
    return fmt::format(
        "UDP port {} is held by pid {} ({}) on {}; stop it, or give this daemon "
        "another sensor.data_port (--port)",
        port, *owner->pid, owner->command, address);
  }
  return fmt::format(
      "UDP port {} is held by a process of another user on {} (`sudo ss -lunp "
      "'sport = :{}'` names it); stop it, or give this daemon another "
      "sensor.data_port (--port)",
      port, address, port);
}

}  // namespace pandarcap
