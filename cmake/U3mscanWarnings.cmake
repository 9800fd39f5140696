# u3mscan_set_warnings(target): the warning level every first-party target builds with.
function(u3mscan_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wno-unused-parameter)
endfunction()

# u3mscan_add_test(name SOURCES ... LIBS ...): one GoogleTest executable, registered with CTest
# test by test so that ctest -j spreads them over the cores.
include(GoogleTest)
function(u3mscan_add_test name)
  cmake_parse_arguments(ARG "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    U3MSCAN_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    U3MSCAN_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared")
  u3mscan_set_warnings(${name})
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT 600)
endfunction()
