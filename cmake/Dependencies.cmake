# Every dependency comes from a Debian 12 package (tools/install-deps.sh installs them).
find_package(Threads REQUIRED)
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(CLI11 CONFIG REQUIRED)
find_package(OpenCV 4 REQUIRED COMPONENTS core imgproc calib3d aruco mcc)
find_package(Ceres REQUIRED)
find_package(OpenImageIO CONFIG REQUIRED)
find_package(ZLIB REQUIRED)
find_package(TIFF REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(LIBRAW REQUIRED IMPORTED_TARGET libraw_r)
if(U3MSCAN_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
find_package(benchmark QUIET)
# The schema tests run the official JSON schemas with Debian's python3-jsonschema, so they use
# the system interpreter, not whatever python3 comes first on PATH.
find_program(U3MSCAN_SYSTEM_PYTHON python3 PATHS /usr/bin NO_DEFAULT_PATH)
