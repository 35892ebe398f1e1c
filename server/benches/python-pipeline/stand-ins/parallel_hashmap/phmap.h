// Stand-in for parallel-hashmap's phmap.h (its repository is not reachable from this machine).
// Polylidar3D uses flat_hash_map only in MeshHelper's half-edge construction for triangle meshes;
// the point-cloud path it is timed on keeps its own std::unordered_map. The real header pulls in
// these standard headers, and Polylidar3D's sources rely on that.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <numeric>
#include <unordered_map>
namespace phmap {
template <typename K, typename V> using flat_hash_map = std::unordered_map<K, V>;
}
