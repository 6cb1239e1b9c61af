#pragma once
// Sphere trees for the broad phase (method.md §6): one tree per body, its topology built by
// Bullet's btDbvt and copied into flat arrays (node indices, bounds side by side) that the refits
// and traversals of every iteration sweep. Internal to the plugin; exposed to tests through this
// header.
#include <BulletCollision/BroadphaseCollision/btDbvt.h>
#include <LinearMath/btTransform.h>

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#if defined(__SSE2__) && !defined(BT_USE_DOUBLE_PRECISION)
#include <immintrin.h>
#define FIBREMSS_SSE_BOUNDS 1
#else
#define FIBREMSS_SSE_BOUNDS 0
#endif

namespace fibremss {

/// Whether bounds a and b overlap (touching counts; NaN never does), as Bullet's Intersect but
/// without branches: Debian's Bullet is built without BT_USE_SSE, so Intersect is a chain of six
/// compare-and-branch, and a traversal's overlap tests go either way about as often.
inline bool boundsOverlap(const btDbvtVolume& a, const btDbvtVolume& b) {
#if FIBREMSS_SSE_BOUNDS
  const __m128 below = _mm_cmple_ps(_mm_load_ps(a.Mins().m_floats), _mm_load_ps(b.Maxs().m_floats));
  const __m128 above = _mm_cmple_ps(_mm_load_ps(b.Mins().m_floats), _mm_load_ps(a.Maxs().m_floats));
  return (_mm_movemask_ps(_mm_and_ps(below, above)) & 7) == 7;  // x, y, z; w is not bounds
#else
  const btVector3 &ai = a.Mins(), &ax = a.Maxs(), &bi = b.Mins(), &bx = b.Maxs();
  return (ai.x() <= bx.x()) & (bi.x() <= ax.x()) & (ai.y() <= bx.y()) & (bi.y() <= ax.y()) &
         (ai.z() <= bx.z()) & (bi.z() <= ax.z());
#endif
}

/// The topology and bounds of a btDbvt over spheres in flat arrays: the inner nodes first, each
/// before its children (node 0 is the root), then the leaves in the order of their spheres'
/// slots. A refit is two sweeps over contiguous memory (leaves, then inner nodes backwards).
/// Refit and traversal on btDbvt's own nodes (one allocation each) took about 1.6× as long
/// (muscle CD at thigh13, resolution 40, one thread).
class FlatSphereTree {
 public:
  /// One node.
  struct Node {
    int32_t children[2] = {-1, -1};  ///< child nodes, or -1 for a leaf
    int32_t sphere = -1;             ///< the leaf's sphere index (a particle or a bone sphere)
  };

  bool empty() const { return nodes_.empty(); }
  const Node& node(int32_t n) const { return nodes_[n]; }
  const btDbvtVolume& bounds(int32_t n) const { return bounds_[n]; }
  /// The node of the sphere in slot k (build order).
  int32_t leaf(size_t k) const { return firstLeaf_ + static_cast<int32_t>(k); }

 protected:
  /// Fills `tree` with one leaf per slot k < count (bounds boundsOf(k), dataAsInt k), optimised
  /// top-down: a balanced tree to start from (it keeps the leaf nodes).
  template <typename BoundsOf>
  static void buildDbvt(btDbvt& tree, size_t count, BoundsOf&& boundsOf);
  /// Copies `tree` (its leaves' dataAsInt: slots 0 … leafCount−1) with its bounds; leaf k's
  /// sphere is k until the caller renames it; sources[n] is the btDbvt node of node n. Allocates
  /// only when the tree grew.
  void flatten(btDbvt& tree, size_t leafCount, std::vector<btDbvtNode*>& sources);
  /// Every inner node's bounds the union of its children's, bottom-up.
  void mergeInner();

  std::vector<Node> nodes_;           ///< inner nodes, then leaves
  std::vector<btDbvtVolume> bounds_;  ///< bounds per node
  int32_t firstLeaf_ = 0;             ///< index of the first leaf (the number of inner nodes)

 private:
  std::vector<std::pair<btDbvtNode*, int32_t>> pending_;  ///< scratch of flatten
};

/// A tree over a muscle's boundary spheres; leaf k holds the sphere `indices[k]` given to build().
/// Refit keeps the topology (method.md §6: rebuild only when asked): a leaf's bounds are its
/// sphere's grown by `margin` (the Verlet skin of refitTree: a tree refit only when a sphere left
/// its fat bounds), an inner node's the union of its children's, recomputed bottom-up in O(n).
/// Re-inserting moved leaves one by one (btDbvt::update with a velocity margin) was measured
/// 2–3× slower at thigh13: while bones move, most spheres leave their fattened bounds every
/// iteration.
class SphereTree : public FlatSphereTree {
 public:
  SphereTree() = default;
  SphereTree(const SphereTree&) = delete;
  SphereTree& operator=(const SphereTree&) = delete;

  /// Inserts one leaf per listed sphere into a btDbvt, optimises it top-down and copies it; keeps
  /// the btDbvt for rebuild() when `rebuildable` (else frees it: ~75 B per particle at thigh13).
  /// Allocates.
  void build(std::span<const uint32_t> indices, std::span<const btVector3> centres,
             std::span<const btScalar> radii, btScalar margin = 0, bool rebuildable = true);
  /// Bounds for the spheres' current centres grown by `margin`, same topology. With a
  /// `snapshot` (indexed like `centres`), also returns the largest squared distance of a centre
  /// from its snapshot and replaces the snapshot by the centres (in the same pass). No allocation.
  btScalar refit(std::span<const btVector3> centres, std::span<const btScalar> radii,
                 btScalar margin = 0, std::span<btVector3> snapshot = {});
  /// Re-inserts every leaf at its sphere into the btDbvt (the thesis' rebuild each step) and
  /// copies it again: a new topology fitted to the current shape. No allocation, unless built
  /// not rebuildable: then the btDbvt is built again from the spheres (allocates, once).
  void rebuild(std::span<const btVector3> centres, std::span<const btScalar> radii,
               btScalar margin = 0);

  /// Counts build, refit and rebuild calls: lists of leaf pairs hold while it is unchanged.
  uint64_t epoch() const { return epoch_; }

 private:
  /// A btDbvt over the spheres at their current centres, optimised top-down.
  void buildTopology(std::span<const btVector3> centres, std::span<const btScalar> radii,
                     btScalar margin);
  /// Copies the btDbvt and names every leaf by its sphere.
  void copyTree();

  uint64_t epoch_ = 0;                  ///< see epoch()
  btDbvt tree_;                         ///< Bullet's tree: the topology, rebuilt on request
  std::vector<uint32_t> spheres_;       ///< sphere of slot k (the indices given to build)
  std::vector<btDbvtNode*> dbvtNodes_;  ///< tree_'s node of each node, owned by tree_
};

/// A bone's spheres in a static tree: built once by btDbvt in the bone frame, its topology never
/// changes; place() re-expresses every node's bounds in world coordinates for the bone's current
/// transform (leaves: the transformed spheres, tight; inner nodes: merged children), O(nodes)
/// per moving bone and no allocation. Queries then run in world space against the muscle trees,
/// with boxes tighter than a muscle box rotated into the bone frame would be.
class BoneSphereTree : public FlatSphereTree {
 public:
  /// Builds the tree over the spheres (bone frame) and places it at the identity. Allocates.
  void build(std::span<const btVector3> centres, std::span<const btScalar> radii);
  /// World bounds and sphere centres for the bone at `boneToWorld`.
  void place(const btTransform& boneToWorld, std::span<const btVector3> centres,
             std::span<const btScalar> radii);

  /// Sphere centres in world coordinates as of the last place().
  const btVector3& centre(int32_t sphere) const { return centres_[sphere]; }
  /// Counts place() calls: lists of leaf pairs with this bone hold while it is unchanged.
  uint64_t placement() const { return placement_; }

 private:
  uint64_t placement_ = 0;          ///< see placement()
  std::vector<btVector3> centres_;  ///< world sphere centres
};

/// A leaf pair of two bodies: the sphere index in the first body and in the second.
struct CandidatePair {
  uint32_t first;   ///< sphere (particle) index in the first body
  uint32_t second;  ///< sphere index in the second body (a particle or a bone sphere)
};

/// The leaf pairs of two bodies whose spheres grown by their reach overlapped when it was
/// listed, reused while both keys it was listed for (SphereTree::epoch, BoneSphereTree::placement)
/// hold: with fat leaves (refitTree's skin) it holds every pair of spheres that can overlap
/// until then. Capacity is
/// fixed when the bodies are added (no allocation in a step); a listing that does not fit is
/// dropped, and the pair is traversed directly until the keys change.
struct CandidateList {
  std::vector<CandidatePair> pairs;  ///< capacity entries, allocated when the bodies are added
  size_t count = 0;                  ///< entries listed
  uint64_t firstKey = 0;             ///< first body's key when listed
  uint64_t secondKey = 0;            ///< second body's key when listed
  bool valid = false;                ///< pairs[0, count) are every candidate for the keys

  /// Listed (and complete) for these keys.
  bool holds(uint64_t first, uint64_t second) const {
    return valid && firstKey == first && secondKey == second;
  }
  /// Starts a listing for the keys (invalid until finish()).
  void start(uint64_t first, uint64_t second) {
    valid = false;
    count = 0;
    firstKey = first;
    secondKey = second;
  }
  /// Appends a pair while room is left; counts it anyway (count > capacity: overflowed).
  void add(uint32_t first, uint32_t second) {
    if (count < pairs.size()) pairs[count] = {first, second};
    ++count;
  }
  /// Ends a listing: valid when everything fitted; returns false when it overflowed.
  bool finish() {
    valid = count <= pairs.size();
    if (!valid) count = 0;
    return valid;
  }
};

/// Two nodes, one of each tree, on a traversal stack.
struct NodePair {
  int32_t first;   ///< node of the first tree
  int32_t second;  ///< node of the second tree
};
/// A traversal stack, reused (one per thread: no allocation once it is deep enough).
using TreeTraversalStack = std::vector<NodePair>;

/// Calls onPair(sphereA, sphereB) for every leaf pair of two trees in the same frame whose
/// bounds overlap, in btDbvt::collideTT's order. Child pairs are written to the stack and kept
/// when they overlap: most fail, and a failed test then costs no branch and no stack traffic.
template <typename OnPair>
void collideTrees(TreeTraversalStack& stack, const FlatSphereTree& a, const FlatSphereTree& b,
                  OnPair&& onPair) {
  if (a.empty() || b.empty() || !boundsOverlap(a.bounds(0), b.bounds(0))) return;
  if (stack.size() < 64) stack.resize(64);
  size_t depth = 0;
  const auto visit = [&](int32_t x, int32_t y) {
    stack[depth] = {x, y};
    depth += boundsOverlap(a.bounds(x), b.bounds(y));
  };
  stack[depth++] = {0, 0};
  while (depth > 0) {
    const NodePair pair = stack[--depth];
    if (depth + 4 > stack.size()) stack.resize(2 * stack.size());  // never in practice
    const FlatSphereTree::Node& x = a.node(pair.first);
    const FlatSphereTree::Node& y = b.node(pair.second);
    if (x.sphere < 0) {
      if (y.sphere < 0) {
        visit(x.children[0], y.children[0]);
        visit(x.children[1], y.children[0]);
        visit(x.children[0], y.children[1]);
        visit(x.children[1], y.children[1]);
      } else {
        visit(x.children[0], pair.second);
        visit(x.children[1], pair.second);
      }
    } else if (y.sphere < 0) {
      visit(pair.first, y.children[0]);
      visit(pair.first, y.children[1]);
    } else {
      onPair(x.sphere, y.sphere);
    }
  }
}

}  // namespace fibremss
