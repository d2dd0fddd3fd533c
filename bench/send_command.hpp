// `pandarcap-bench send`: the harness's traffic generator on its own (bench/udp_traffic.hpp).
#pragma once

namespace pandarcap::bench {

// Parses the subcommand's options (argv[0]: "pandarcap-bench send"), sends, and reports; returns
// the exit status (its --help says which).
int run_send(int argc, char** argv);

}  // namespace pandarcap::bench
