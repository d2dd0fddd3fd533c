// The thread census: which test cases start threads, in the test binary or in a binary they run.
//
// The ThreadSanitizer job runs only the tests tagged [threads] (the others are pure logic, which
// TSan has nothing to say about, and they cost it a third of its time). That is safe only while
// every test that starts a thread carries the tag, so the release job checks it: there the test
// binary runs with tests/thread_census_preload.cpp preloaded (ctest's LD_PRELOAD, inherited by
// every binary a test starts), which notes each pthread_create of ours, and a listener compares
// each test case's threads with its tag. A test that starts threads without [threads] fails the
// run (main() returns 1, the message says which test and which binaries); a [threads] test that
// started none gets a warning (it may have returned early where a tool is missing).
#pragma once

namespace pandarcap::test {

// Whether a test case of this run started threads without the [threads] tag.
bool thread_census_failed();

}  // namespace pandarcap::test
