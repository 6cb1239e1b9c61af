#pragma once
// Sphere trees for the broad phase (method.md §6) on Bullet's btDbvt: one tree per body, leaves
// are sphere bounds whose dataAsInt is the sphere's index (a particle or a bone sphere), never a
// pointer. Internal to the plugin; exposed to tests through this header.
#include <BulletCollision/BroadphaseCollision/btDbvt.h>
#include <LinearMath/btTransform.h>

#include <cstdint>
#include <span>
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

/// One btDbvt over spheres; leaf k holds the sphere `indices[k]` given to build(). Refit keeps the
/// topology (method.md §6: rebuild only when asked): a leaf's bounds are its sphere's grown by
/// `margin` (the Verlet skin of refitTree: a tree refit only when a sphere left its fat bounds),
/// an inner node's the union of its children's, recomputed bottom-up in O(n). Re-inserting moved
/// leaves one by one (btDbvt::update with a velocity margin) was measured 2–3× slower at thigh13:
/// while bones move, most spheres leave their fattened bounds every iteration.
class SphereTree {
 public:
  SphereTree() = default;
  SphereTree(const SphereTree&) = delete;
  SphereTree& operator=(const SphereTree&) = delete;

  /// Inserts one leaf per listed sphere and optimises the tree top-down. Allocates.
  void build(std::span<const uint32_t> indices, std::span<const btVector3> centres,
             std::span<const btScalar> radii, btScalar margin = 0);
  /// Bounds for the spheres' current centres grown by `margin`, same topology. With a
  /// `snapshot` (indexed like `centres`), also returns the largest squared distance of a centre
  /// from its snapshot and replaces the snapshot by the centres (in the same pass). No allocation.
  btScalar refit(std::span<const uint32_t> indices, std::span<const btVector3> centres,
                 std::span<const btScalar> radii, btScalar margin = 0,
                 std::span<btVector3> snapshot = {});
  /// Re-inserts every leaf at its sphere (the thesis' rebuild each step): a new topology fitted
  /// to the current shape. No allocation.
  void rebuild(std::span<const uint32_t> indices, std::span<const btVector3> centres,
               std::span<const btScalar> radii, btScalar margin = 0);

  const btDbvtNode* root() const { return tree_.m_root; }
  size_t leafCount() const { return leaves_.size(); }
  /// Counts build, refit and rebuild calls: lists of leaf pairs hold while it is unchanged.
  uint64_t epoch() const { return epoch_; }

 private:
  /// Lists the inner nodes children-first into inner_.
  void orderInnerNodes();

  uint64_t epoch_ = 0;                ///< see epoch()
  btDbvt tree_;                       ///< the Bullet tree
  std::vector<btDbvtNode*> leaves_;   ///< leaf of the k-th sphere, owned by tree_
  std::vector<btDbvtNode*> inner_;    ///< inner nodes, every child before its parent
  std::vector<btDbvtNode*> pending_;  ///< scratch of orderInnerNodes, sized at build
};

/// A traversal stack for collideTrees (Bullet's node-pair entries), reused: sized once, it grows
/// only if a traversal needs more (never in practice).
using TreeTraversalStack = btAlignedObjectArray<btDbvt::sStkNN>;

/// Reports every leaf pair of two trees in the same frame whose bounds overlap, like
/// btDbvt::collideTTpersistentStack on a stack of the caller's (one per thread: no allocation).
void collideTrees(TreeTraversalStack& stack, const btDbvtNode* a, const btDbvtNode* b,
                  btDbvt::ICollide& policy);

/// A bone's spheres in a static tree: built once by btDbvt in the bone frame, its topology never
/// changes; place() re-expresses every node's bounds in world coordinates for the bone's current
/// transform (leaves: the transformed spheres, tight; inner nodes: merged children), O(nodes)
/// per moving bone and no allocation. Queries then run in world space against the muscle trees,
/// with boxes tighter than a muscle box rotated into the bone frame would be.
class BoneSphereTree {
 public:
  /// One node; children come after their parent, so a reverse sweep refits bottom-up.
  struct Node {
    int32_t children[2] = {-1, -1};  ///< child nodes, or -1 for a leaf
    int32_t sphere = -1;             ///< the leaf's sphere index
  };

  /// Builds the tree over the spheres (bone frame) and places it at the identity. Allocates.
  void build(std::span<const btVector3> centres, std::span<const btScalar> radii);
  /// World bounds and sphere centres for the bone at `boneToWorld`.
  void place(const btTransform& boneToWorld, std::span<const btVector3> centres,
             std::span<const btScalar> radii);

  bool empty() const { return nodes_.empty(); }
  const Node& node(int32_t n) const { return nodes_[n]; }
  const btDbvtVolume& bounds(int32_t n) const { return bounds_[n]; }
  /// Sphere centres in world coordinates as of the last place().
  const btVector3& centre(int32_t sphere) const { return centres_[sphere]; }
  /// Counts place() calls: lists of leaf pairs with this bone hold while it is unchanged.
  uint64_t placement() const { return placement_; }

 private:
  uint64_t placement_ = 0;            ///< see placement()
  std::vector<Node> nodes_;           ///< node 0 is the root
  std::vector<btDbvtVolume> bounds_;  ///< world bounds per node
  std::vector<btVector3> centres_;    ///< world sphere centres
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

/// A muscle tree node paired with a bone tree node, on the traversal stack.
struct MuscleBoneNodes {
  const btDbvtNode* muscle;  ///< node of the muscle's btDbvt
  int32_t bone;              ///< node of the bone tree
};
/// A reusable traversal stack for collideWithBone.
using MuscleBoneStack = std::vector<MuscleBoneNodes>;

/// Calls onPair(muscleLeaf, sphere) for every muscle leaf whose bounds overlap the bounds of a
/// bone sphere (both in world space), descending both trees like btDbvt::collideTT. Child pairs
/// are tested before they are pushed: most fail, and a failed test then costs no stack traffic.
template <typename OnPair>
void collideWithBone(MuscleBoneStack& stack, const btDbvtNode* muscleRoot,
                     const BoneSphereTree& bone, OnPair&& onPair) {
  if (!muscleRoot || bone.empty() || !boundsOverlap(muscleRoot->volume, bone.bounds(0))) return;
  size_t depth = 0;
  // Written always, kept when they overlap: no branch on the test.
  const auto visit = [&](const btDbvtNode* muscle, int32_t boneNode) {
    stack[depth] = {muscle, boneNode};
    depth += boundsOverlap(muscle->volume, bone.bounds(boneNode));
  };
  if (stack.size() < 64) stack.resize(64);
  stack[depth++] = {muscleRoot, 0};
  while (depth > 0) {
    const MuscleBoneNodes pair = stack[--depth];
    if (depth + 4 > stack.size()) stack.resize(2 * stack.size());  // never in practice
    const BoneSphereTree::Node& b = bone.node(pair.bone);
    if (pair.muscle->isinternal()) {
      if (b.sphere < 0) {
        visit(pair.muscle->childs[0], b.children[0]);
        visit(pair.muscle->childs[1], b.children[0]);
        visit(pair.muscle->childs[0], b.children[1]);
        visit(pair.muscle->childs[1], b.children[1]);
      } else {
        visit(pair.muscle->childs[0], pair.bone);
        visit(pair.muscle->childs[1], pair.bone);
      }
    } else if (b.sphere < 0) {
      visit(pair.muscle, b.children[0]);
      visit(pair.muscle, b.children[1]);
    } else {
      onPair(pair.muscle, b.sphere);
    }
  }
}

}  // namespace fibremss
