// pandarcapd's --help: every option, what it sets and the exit statuses, in one text that
// parse_command_line() hands to CliArgs (which also takes each option's name from it for
// did-you-mean). The docs check (tests/test_readme_commands.cpp) reads it through --help.
#pragma once

#include <string_view>

namespace pandarcap {

inline constexpr std::string_view kPandarcapdUsage =
    R"(Usage: pandarcapd [options]                  live capture from the sensor
       pandarcapd --simulate [options]       live path fed by a built-in simulated sensor
       pandarcapd --replay FILE [options]    process a recording (pcap, pcap.zst, MCAP)

Captures a Hesai Pandar40P, Pandar64, PandarXT32, PandarXT16 or PandarQT128 (the model from its
packets, or --sensor-model): receives its UDP packets, decodes them into frames, and writes
OUTPUT-DIR/frames/*.pcd, OUTPUT-DIR/raw/*.pcap (+ calibration.csv), with --mcap
OUTPUT-DIR/mcap/*.mcap (Foxglove, ros2 bag) and, every second,
OUTPUT-DIR/health/pandarcap.prom and health.jsonl. SIGTERM/SIGINT stop it cleanly, SIGHUP
starts new recording files.

Configuration:
  -c, --config FILE      TOML configuration (see config/pandarcap.toml); without it the
                         defaults apply, and the options below override either
  --check-config         check everything the start checks without network: the configuration,
                         the calibration file, the decoder, and that every output directory is
                         (or can be made) writable by this user, and try the live view's port
                         (one in use is a warning: the capture would run); print the result and
                         exit (0, 73 outputs, 78 configuration or calibration)
  --print-config         print the effective configuration as TOML and exit
  --print-calibration    print the angle-correction table in effect (from the sensor, the
                         calibration file or the nominal table, as calibration_source says) as
                         CSV and exit

Sources:
  --simulate             start a simulated sensor that sends over loopback to the daemon's own
                         socket (127.0.0.1, a free port unless --port is given)
  --replay FILE          read packets from a recording instead of the network; exits when
                         the file is done. FILE: pcap or pcapng, either compressed with zstd
                         (.pcap.zst, or a killed run's .pcap.zst.part: read to its cut), or
                         MCAP with packets (--mcap-packets; its pandar_msgs/msg/PandarPacket
                         messages, timed by their log time); told apart by the first bytes
  --top-speed            replay as fast as the decoder goes (the default)
  --rate X               replay at X times the recorded pace (1 = real time)
  --duration S           stop after S seconds (live and simulated runs)

Overrides (same names as the configuration keys):
  --output-dir DIR       output.directory (default pandarcap-output)
  --calibration FILE     sensor.calibration_file (default: the model's nominal table; with
                         --replay, the recording's own first: NAME.calibration.csv beside a
                         pcap, the attachment of an MCAP file)
  --calibration-source S sensor.calibration_source: auto (default: the sensor over PTC if it
                         answers, else the file, else nominal), sensor, file or nominal
  --ptc-port N           sensor.ptc_port (default 9347); with --simulate: ask this port on
                         127.0.0.1 instead of the simulated sensor's own
  --status-interval S    sensor.status_interval_seconds (default 5): poll the sensor's status
                         (PTP/GPS lock, motor, temperatures) over PTC; 0 = off
  --host-ip IP           sensor.host_ip (default 0.0.0.0)
  --port N               sensor.data_port (default 2368); with --replay: only datagrams to N
                         (not for MCAP: its packets carry no addresses)
  --receiver R           input.receiver: socket (default: a UDP socket read with recvmmsg, no
                         privilege) or packet_ring (an AF_PACKET TPACKET_V3 ring on --interface,
                         as tcpdump reads: less CPU, needs CAP_NET_RAW; docs/deploy.md)
  --interface IFACE      sensor.interface: the network interface packet_ring reads (e.g. eth1)
  --sensor-ip IP         sensor.sensor_ip: drop (and count) datagrams from other sources;
                         without it, the first address to send a packet is the sensor's (not
                         for a replayed MCAP: its packets carry no addresses)
  --cut-angle DEG        sensor.cut_angle (default 0)
  --frame AXES           sensor.frame: hesai (default; the sensor's axes, y at azimuth 0) or ros
                         (REP 103: x forward, y left, z up)
  --pcd-fields LAYOUT    output.pcd_fields: pcl (default: float intensity, PCL's PointXYZI),
                         pandarcap, velodyne (PointXYZIRT) or autoware (nebula's PointXYZIRCAEDT)
  --pcd-compression C    output.pcd_compression: none (default) or lzf (DATA binary_compressed)
  --pcap-compression C   output.pcap_compression: none (default: raw/NAME.pcap) or zstd
                         (raw/NAME.pcap.zst, which tshark and --replay read as it is)
  --min-free-bytes N     output.min_free_bytes: delete the oldest of pandarcap's files to keep
                         N bytes free on each output file system, never less than the health
                         files' 32 MiB plus 2 s of writing (default 0: no floor, nothing deleted)
  --upload               output.upload = true: raw/ and mcap/ leave by upload (pandarcap-upload@
                         NAME.timer); the health says how far it is behind, and counts files
                         removed before they were uploaded
  --upload-frames        output.upload_frames = true: frames/ is uploaded too
  --min-range M          sensor.min_range (default 0.3)
  --max-range M          sensor.max_range (default 200)
  --dual-return-distance-threshold M
                         sensor.dual_return_distance_threshold (default 0.1)
  --firing-time-correction
                         sensor.firing_time_correction = true
  --sensor-model NAME    sensor.model: auto (default: from the packets), Pandar40P, Pandar64,
                         PandarXT32, PandarXT16 or PandarQT128 (any case); with --simulate,
                         the model the simulated sensor is
  --rpm N                simulated (and expected) motor speed, 600 or 1200
  --return-mode MODE     simulated (and expected) return mode: dual, strongest or last
  --udp-sequence         the simulated sensor appends a UDP sequence number
  --decoder NAME         decoder: auto (default), scalar, sse4, avx2, avx512, neon, sve, sve2
  --mcap                 output.mcap = true: also write MCAP files (PointCloud2 frames, health)
  --mcap-packets         output.mcap_packets = true: every datagram into the MCAP files too
  --mcap-compression C   output.mcap_compression: the MCAP chunks' lz4 (default; about a
                         third of zstd's CPU), zstd (files ~1.26x smaller) or none
  --mcap-only            output.mcap = true, output.frames = false, output.pcap = false; with
                         --replay FILE this converts a capture to MCAP
  --foxglove-port N      live.foxglove = true, live.port = N: a live view for Foxglove (Open
                         connection, ws://HOST:N) of the frames, health and sensor status, on
                         live.address (default 127.0.0.1); a port in use is tried again every
                         10 s, the capture running and the health degraded until it binds
  --latency-budget-ms N  latency.budget_ms (default 5): how long a datagram may wait before the
                         receive thread drains the socket; 0 = wake for every datagram
  --log-level LEVEL      trace, debug, info, warn, error, critical, off
  --max-clock-offset S   health.max_sensor_clock_offset_seconds (default 1): a sensor clock
                         further from the host's makes the state degraded; 0 = not checked
                         (replays of recordings from an unsynchronised sensor)
  --allow-root           run even as root (refused otherwise: pandarcapd needs no privilege,
                         and a parser of network packets should not hold one; the systemd unit
                         runs it as the user pandarcap)
  --version              print the version and exit
  -h, --help             this text

Exit status: 0 done, 1 runtime failure, 64 usage error, 65 the replayed recording is not
whole (damaged or cut short: what could be read was replayed, and the summary, the log and the
last health record say what was not), 66 capture file unreadable,
69 the sensor did not give its calibration (calibration_source = "sensor"), 73 output
directory not writable or in use by another pandarcapd, 77 run as root without --allow-root,
78 invalid configuration or calibration file.
)";

}  // namespace pandarcap
