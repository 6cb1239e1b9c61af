#pragma once
// Union-find over indices (particles, vertices): the pieces a muscle tears into, the patches of
// a bone area on a muscle's surface. In a parent array a root is its own parent.
#include <cstdint>
#include <vector>

namespace fibremss {

/// The union-find root of `i` in `parent`, halving the path on the way.
inline uint32_t unionFindRoot(std::vector<uint32_t>& parent, uint32_t i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

/// Joins the pieces of i and j under the smaller of their roots: each piece's root is its
/// smallest index, whatever the order of the joins.
inline void unionFindJoin(std::vector<uint32_t>& parent, uint32_t i, uint32_t j) {
  const uint32_t a = unionFindRoot(parent, i), b = unionFindRoot(parent, j);
  if (a < b) parent[b] = a;
  if (b < a) parent[a] = b;
}

}  // namespace fibremss
