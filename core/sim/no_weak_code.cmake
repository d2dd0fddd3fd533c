# cmake -DARCHIVE=lib.a -DNM=nm -P no_weak_code.cmake: fails when the archive defines a weak code
# symbol (nm type W), naming it (core/sim/CMakeLists.txt says why).
execute_process(COMMAND ${NM} -C --defined-only ${ARCHIVE} OUTPUT_VARIABLE symbols
                COMMAND_ERROR_IS_FATAL ANY)
string(REGEX MATCHALL "\n[0-9a-f]+ W [^\n]+" weak "\n${symbols}")
if(weak)
  list(JOIN weak "" listed)
  message(FATAL_ERROR "${ARCHIVE} is built without ThreadSanitizer's instrumentation and defines "
                      "these inline functions out of line; the program may keep these copies, "
                      "unchecked (move the code that needs them to pandarcap_sim):${listed}")
endif()
