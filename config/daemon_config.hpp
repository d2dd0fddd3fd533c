// Everything pandarcapd can be configured with, and its defaults. The TOML file
// (config/pandarcap.toml documents every key) maps onto this one-to-one: table [sensor] holds
// the established LiDAR-driver parameter names, then [ring], [arenas], [output], [health],
// [threads], [latency] and [live]. The defaults are what `pandarcapd --replay FILE` runs with
// when no config file is given.
#pragma once

#include <cstdint>
#include <string>

namespace pandarcap {

struct SensorSection {
  std::string sensor_ip;  // accept datagrams only from this IPv4; "" = the first to send a packet
  std::string host_ip = "0.0.0.0";     // local address the UDP socket binds to
  std::string multicast_ip;            // group to join; "" = unicast/broadcast
  std::string multicast_interface_ip;  // local interface address for the join; "" = any
  // The network interface input.receiver = "packet_ring" reads (required there; the socket
  // receiver ignores it).
  std::string interface;
  std::uint16_t data_port = 2368;                                 // 1..65535
  std::uint64_t udp_socket_receive_buffer_size_bytes = 8u << 20;  // requested SO_RCVBUF
  // The sensor model: "auto" (from the packets: core/sensors/model_detection.hpp) or one of
  // "Pandar40P", "Pandar64", "PandarXT32", "PandarXT16", "PandarQT128" (any case).
  std::string model = "auto";
  std::string return_mode = "any";              // expected: "any", "last", "strongest", "dual"
  int rotation_speed = 600;                     // expected motor speed, RPM: 600 or 1200
  double cut_angle = 0.0;                       // degrees, [0, 360)
  double min_range = 0.3;                       // metres, >= 0
  double max_range = 200.0;                     // metres, > min_range
  double dual_return_distance_threshold = 0.1;  // metres, >= 0
  std::string calibration_file;                 // CSV; "" = the nominal table
  // Where the angles come from: "auto" (the sensor over PTC if it answers, else
  // calibration_file, else nominal), "sensor", "file" or "nominal".
  std::string calibration_source = "auto";
  std::uint16_t ptc_port = 9347;        // the sensor's TCP control port (PTC) at sensor_ip
  std::uint32_t ptc_timeout_ms = 2000;  // to connect, then for each whole answer; 100..60000
  double status_interval_seconds = 5;   // poll the sensor's status over PTC; 0 = off
  bool firing_time_correction = false;
  // The axes points are written in (PCD, MCAP): "hesai" (the sensor's: y at azimuth 0, x at 90°,
  // z up) or "ros" (REP 103: x forward, y left, z up).
  std::string frame = "hesai";
};

// How datagrams are taken from the kernel (daemon/source/): "socket", a UDP socket read with
// recvmmsg (no privilege), or "packet_ring", an AF_PACKET TPACKET_V3 ring on sensor.interface
// that the kernel fills and this host reads without a system call per batch (CAP_NET_RAW).
struct InputSection {
  std::string receiver = "socket";
};

struct RingSection {
  std::uint32_t slots = 4096;        // packet slots between receive and decode; power of two
  std::uint32_t receive_batch = 64;  // datagrams per recvmmsg; 1..1024 and <= slots
};

struct ArenaSection {
  std::uint32_t count = 4;                   // frame arenas in the pool; 2..64
  std::uint32_t points_per_frame = 180'000;  // 1800 firings x 40 channels x 2 returns + 25 %
  std::uint32_t packets_per_frame = 512;     // raw packets kept per frame for the pcap
};

struct OutputSection {
  std::string directory = "pandarcap-output";  // frames/, raw/, mcap/, health/ go under it
  // The name the recordings give the machine they were made on: the MCAP files' "foxglove"
  // metadata (deviceName, what Foxglove's importers file a recording under), their "pandarcap"
  // metadata and sensor.json. "" = this host's name (gethostname), resolved at start.
  std::string device_name;
  bool frames = true;              // write frames as PCD
  std::string pcd_fields = "pcl";  // PCD field layout: "pcl", "pandarcap", "velodyne", "autoware"
  // PCD DATA encoding: "none" (binary) or "lzf" (binary_compressed, as PCL writes it).
  std::string pcd_compression = "none";
  std::uint32_t frame_decimation = 1;  // write every Nth frame; >= 1
  // A partial frame covering less than this fraction of a revolution (in azimuth and in
  // single-return packets at rotation_speed) is a fragment: counted (frames_fragment), not
  // written. 0 = write every frame; 0..1.
  double frames_min_fraction = 0.25;
  std::uint64_t frames_max_files = 0;          // retention; 0 = unlimited
  std::uint64_t frames_max_bytes = 0;          // retention; 0 = unlimited
  bool pcap = true;                            // record raw packets as pcap
  std::uint64_t pcap_rotate_bytes = 1u << 30;  // start a new file after this many; 0 = never
  std::uint32_t pcap_rotate_seconds = 0;       // start a new file after this long; 0 = never
  std::uint64_t pcap_max_files = 0;            // retention; 0 = unlimited
  std::uint64_t pcap_max_bytes = 0;            // retention; 0 = unlimited
  std::string pcap_compression = "none";       // "none" (NAME.pcap) or "zstd" (NAME.pcap.zst)
  int pcap_compression_level = 1;              // zstd level: -7 (fastest) .. 19
  // MCAP (Foxglove, ros2 bag): frames as sensor_msgs/msg/PointCloud2, health as JSON, the
  // calibration attached; optionally the raw packets. In mcap/ under the directory.
  bool mcap = false;
  bool mcap_packets = false;             // also each datagram (pandar_msgs/msg/PandarPacket)
  std::string mcap_compression = "lz4";  // chunk compression: "lz4", "zstd" or "none"
  int mcap_compression_level = 1;        // zstd level: -7 (fastest) .. 19; 1 = zstd's fast default
                                         // (lz4: below 3 fast, 3..12 high compression)
  std::uint64_t mcap_chunk_bytes = 4u << 20;  // uncompressed messages per chunk, about
  bool mcap_chunk_crc = false;  // every chunk's CRC-32 (off: 0, "not computed"; zstd's checksum)
  std::uint64_t mcap_rotate_bytes = 1u << 30;  // start a new file after this many; 0 = never
  std::uint32_t mcap_rotate_seconds = 0;       // start a new file after this long; 0 = never
  std::uint64_t mcap_max_files = 0;            // retention; 0 = unlimited
  std::uint64_t mcap_max_bytes = 0;            // retention; 0 = unlimited
  std::string mcap_frame_id = "pandar";        // header.frame_id of every PointCloud2
  std::string mcap_points_topic = "/pandar/points";
  std::string mcap_health_topic = "/pandar/health";
  std::string mcap_packets_topic = "/pandar/packets";
  // A floor of free space on each output file system: below it the oldest of pandarcap's own
  // files (frames, recordings, MCAP; earlier runs' too) are deleted. The floor is the larger of
  // the two, and never less than the health files' 32 MiB plus 2 s of writing, where it can act.
  // Both 0 (the default): no floor; nothing of ours is removed but by retention.
  std::uint64_t min_free_bytes = 0;
  double min_free_percent = 0;  // of the file system's size; 0..90
  // A recording still being written (pcap, pcap.zst, MCAP) and health.jsonl have their data
  // synced to the disk this often, so a power cut loses at most about this much of them. Finished
  // files are always synced before they get their final name. 0 = only then.
  double sync_interval_seconds = 2.0;
  // Recordings leave the vehicle by upload (systemd/pandarcap-upload@.service): the health says
  // how far it is behind, and a file removed before it was uploaded is counted and named. With
  // upload_frames, frames/ is an upload directory too.
  bool upload = false;
  bool upload_frames = false;
};

struct HealthSection {
  std::string sensor_name;  // the `sensor` label on every metric; "" = the model's lower-case name
  double no_data_timeout_seconds = 1.0;          // silence longer than this: state no_data
  double max_sensor_clock_offset_seconds = 1.0;  // sensor clock further off: degraded; 0 = off
  bool prometheus = true;                        // health/pandarcap.prom
  bool jsonl = true;                             // health/health.jsonl
  std::uint64_t jsonl_rotate_bytes = 64u << 20;  // rotate health.jsonl; 0 = never
  std::string directory;        // health.jsonl (and pandarcap.prom); "" = OUTPUT-DIR/health
  std::string prometheus_file;  // the .prom file; "" = HEALTH-DIR/pandarcap.prom
  // Fewer hours of disk left than this at the last minute's write rate: degraded. 0 = off.
  double min_hours_left = 0;
  // Where the health files go while their own directory cannot be written (a read-only or failing
  // disk): "" = the systemd unit's RuntimeDirectory ($RUNTIME_DIRECTORY), else
  // $XDG_RUNTIME_DIR/pandarcap, else /tmp/pandarcap-UID (daemon_options.cpp).
  std::string fallback_directory;
};

// Optional placement of the threads on a dedicated PC (best effort: what the limits refuse is
// logged, never fatal). CPU -1 = not pinned; priority 0 = normal scheduling, 1..99 = SCHED_FIFO.
struct ThreadsSection {
  int receive_cpu = -1;
  int decode_cpu = -1;
  int writer_cpu = -1;
  int receive_priority = 0;
  int decode_priority = 0;
  int writer_priority = 0;
  bool lock_memory = false;  // mlockall once started
};

// How long a datagram may wait in the socket before the receive thread takes it. The thread
// then drains the socket in full batches and wakes the decoder once per drain, instead of
// waking (and waking the decoder) for every datagram. 0 = wake per datagram (lowest latency,
// most CPU at one sensor's rate).
struct LatencySection {
  std::uint32_t budget_ms = 5;  // 0..1000
};

// The live view: a Foxglove WebSocket server (foxglove.websocket.v1) showing the frames, the
// health record and the sensor's status as they are made (daemon/live/). Read-only; off unless
// asked for. An address other than 127.0.0.1 is logged as a warning at start.
struct LiveSection {
  bool foxglove = false;
  std::string address = "127.0.0.1";  // the IPv4 address the server listens on
  std::uint16_t port = 8765;          // 1..65535
  std::uint32_t max_clients = 4;      // connections beyond this are refused; 1..64
};

struct DaemonConfig {
  std::string log_level = "info";  // trace, debug, info, warn, error, critical, off
  // Packet decoder: "auto" (the fastest SIMD target this CPU runs), "scalar" (the reference),
  // or a SIMD target: "sse4", "avx2", "avx512", "neon", "sve", "sve2". A target this CPU cannot
  // run stops the daemon at start-up (exit 78); it never falls back silently.
  std::string decoder = "auto";
  SensorSection sensor;
  InputSection input;
  RingSection ring;
  ArenaSection arenas;
  OutputSection output;
  HealthSection health;
  ThreadsSection threads;
  LatencySection latency;
  LiveSection live;
};

}  // namespace pandarcap
