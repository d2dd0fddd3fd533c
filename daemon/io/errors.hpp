// The one place a failed system call becomes an exception.
//
// Every file and socket call in the daemon reports failure the same way: a std::system_error that
// carries the errno (callers branch on it: ENOSPC, EEXIST, EWOULDBLOCK...) and says what was being
// done and to what ("cannot write 'raw/x.pcap.part'"). Nothing outside daemon/io/ and daemon/pcap/
// builds one by hand.
#pragma once

#include <string_view>

namespace pandarcap::io {

// Throws std::system_error for `error` with the message `what` ("simulator socket").
[[noreturn]] void throw_error(int error, std::string_view what);
// The same for `what 'path'` ("cannot open '/var/lib/pandarcap/frames/x.pcd'").
[[noreturn]] void throw_error(int error, std::string_view what, std::string_view path);

// The same with the current errno (read first, before anything can change it). An errno of 0
// (stdio is not obliged to set it) is reported as EIO rather than as "Success".
[[noreturn]] void throw_errno(std::string_view what);
[[noreturn]] void throw_errno(std::string_view what, std::string_view path);

}  // namespace pandarcap::io
