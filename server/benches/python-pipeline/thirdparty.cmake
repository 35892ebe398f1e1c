# Replaces Polylidar3D 1.0.9's thirdparty/CMakeLists.txt, which clones four repositories from
# GitHub at configure time (not reachable from this machine): Eigen from Debian
# (libeigen3-dev), pybind11 from PyPI, and the stand-ins beside this file for parallel-hashmap and
# marl, which only the mesh paths use. Configure with -DSTAND_INS=<dir of the stand-ins> and
# -DCMAKE_FIND_PACKAGE_TARGETS_GLOBAL=ON (src/Python needs the pybind11 targets found here).
find_package(pybind11 CONFIG REQUIRED)
add_library(eigen INTERFACE)
target_include_directories(eigen INTERFACE /usr/include/eigen3)
add_library(phmap INTERFACE)
target_include_directories(phmap INTERFACE ${STAND_INS})
add_library(marl INTERFACE)
target_include_directories(marl INTERFACE ${STAND_INS})
