# Checks that FILES (test file names, "|"-separated) are exactly the files that hold the tests
# SPECS ("|"-separated Catch2 test specs) select in TESTS (the whole test binary). FILES is the
# list LIST in tests/CMakeLists.txt that a smaller test binary is built from: CI's ARM64 tests
# (arm64_ci_test_files) or the TSan job's (tsan_test_files).
# cmake -DTESTS=... -DSPECS=... -DFILES=... -DLIST=... -P check_test_files.cmake
string(REPLACE "|" ";" specs "${SPECS}")
string(REPLACE "|" ";" listed "${FILES}")
set(needed "")
foreach(spec IN LISTS specs)
  # Catch2 v2 exits with the number of tests listed, so the output is what is checked.
  execute_process(COMMAND "${TESTS}" --list-tests -v high "${spec}" OUTPUT_VARIABLE out
                  ERROR_VARIABLE err)
  if(NOT out MATCHES "[1-9][0-9]* matching test cases")
    message(FATAL_ERROR "'${TESTS} --list-tests ${spec}' listed no test:\n${out}${err}")
  endif()
  string(REGEX MATCHALL "tests/test_[a-z0-9_]+\\.cpp:" locations "${out}")
  foreach(location IN LISTS locations)
    string(REGEX REPLACE "^tests/(.*):$" "\\1" file "${location}")
    list(APPEND needed "${file}")
  endforeach()
endforeach()
list(REMOVE_DUPLICATES needed)
set(missing ${needed})
list(REMOVE_ITEM missing ${listed})
set(unused ${listed})
list(REMOVE_ITEM unused ${needed})
if(missing)
  list(JOIN missing ", " missing)
  message(FATAL_ERROR "tests/CMakeLists.txt, ${LIST}: the tests '${SPECS}' are also in "
                      "${missing}; add them to the list")
endif()
if(unused)
  list(JOIN unused ", " unused)
  message(FATAL_ERROR "tests/CMakeLists.txt, ${LIST}: ${unused} hold none of the tests "
                      "'${SPECS}'; remove them from the list")
endif()
list(LENGTH needed count)
message(STATUS "${LIST}: the ${count} files of the tests '${SPECS}' are the ones listed")
