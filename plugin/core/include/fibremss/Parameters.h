#pragma once
// Definition structs with defaults (Box2D style): everything a scene can set about the model.
// All quantities are SI (metres, kilograms, seconds, newtons).
#include <LinearMath/btScalar.h>
#include <LinearMath/btVector3.h>

#include <cstdint>
#include <limits>
#include <string>

#include "fibremss/TaskScheduler.h"

namespace fibremss {

/// How particles of one muscle are linked by springs (method.md §3).
enum class SpringLayout : uint8_t {
  NearestNeighbours,  ///< each particle to its N nearest; union of the pairs (default)
  Delaunay,           ///< edges of the Delaunay tetrahedralization of the particles
  Lattice6,           ///< fibre grid × samples, 6-neighbourhood
  Lattice26,          ///< fibre grid × samples, 26-neighbourhood
};

/// How a muscle's springs share the network's stiffness.
enum class SpringStiffness : uint8_t {
  /// k = κ/L0 times the volume of muscle around the spring per length of spring (its particles'
  /// quarters of the interior tetrahedra over the Σ L0 of their springs), scaled so that the
  /// network's Σ k·L0² is that of κ/L0 (default). A fibre-sampled muscle has as many fibres through
  /// a thin end as through its
  /// belly, so with κ/L0 the end is as stiff as the belly; a continuum's is E·A, and the end
  /// stretches more (fusiform's equilibrium: 1.46 mm RMS to the CalculiX reference by length,
  /// 0.39 mm by volume).
  Volume,
  Length,  ///< k = κ / L0 (the thesis, method.md §3)
};

/// Springs and masses of one muscle (method.md §3).
struct SpringParameters {
  SpringLayout layout = SpringLayout::NearestNeighbours;  ///< spring layout
  int neighbours = 18;                                    ///< N for the N-nearest layout
  btScalar kappa = 1.0;  ///< material constant κ [N]; spring stiffness k = κ / L0
  SpringStiffness stiffness = SpringStiffness::Volume;  ///< how the springs share κ
  btScalar damping = -1;  ///< damping coefficient c [N·s/m]; < 0: Zeleny's estimate × scale
  /// Factor on Zeleny's estimate (used when damping < 0). The estimate damps the stiffest
  /// modes critically and so over-damps the slow, whole-muscle ones, which then creep. Measured
  /// (fusiform, single iterations after the pull): within 1 % of the settled spring deviation
  /// after 2087 iterations at 1, 1088 at 0.5, 106 at 0.1; but at 0.3 and below the noisy
  /// sphere-planes scene flings particles through its planes (springs to 230×), at 0.4 it
  /// holds: 0.5 keeps that margin.
  btScalar dampingScale = 0.5;
  btScalar density = 1060;  ///< muscle density [kg/m³]; mass = density·volume / particles
  /// Local volume preservation: a bulk modulus K against each Delaunay tetrahedron's volume
  /// change (energy ½·K·(V − V0)²/V0 per tetrahedron), as a multiple of the spring network's
  /// Young's modulus E = Σk·L0² / 3V [1] (K in Pa = this × E; 0: off; < 0: the multiple
  /// volumeMultipleFor(poissonRatio), the default: 6.27 at 0.485; volumeMultiple says which
  /// applies).
  btScalar volumeStiffness = -1;
  /// Poisson ratio of the spring network with its local volume terms when volumeStiffness < 0
  /// (the default) [1], in [0.25, 0.5): muscle is nearly incompressible (about 0.49).
  btScalar poissonRatio = btScalar(0.485);
  /// Whole-muscle volume preservation: a bulk modulus K against the change of the volume the
  /// muscle's interior tetrahedra enclose (energy ½·K·(V − V0)²/V0 per muscle, a pressure on the
  /// boundary of the particles), as a multiple of E like volumeStiffness [1] (0: off).
  btScalar enclosedVolumeStiffness = 0;
  /// The local volume terms on fewer, larger tetrahedra: 1 takes the Delaunay tetrahedra of all
  /// the particles; c > 1 those of a subset in which no two particles lie closer than c times
  /// the first one's distance to its nearest particle (kept greedily in particle order) [1].
  btScalar volumeCoarsening = 1;
  /// Stiffness of a spring along the local fibre direction over one across it [1]: a spring at
  /// angle θ to the fibres gets k = κ/L0 · (ratio·cos²θ + sin²θ) (1: isotropic).
  btScalar fibreStiffnessRatio = 1;
  /// Largest current / rest length a spring may end a solver iteration or a step at [1] (0: no
  /// limit): a position projection after each integration (StrainLimit.h). Passive skeletal
  /// muscle tears beyond about 1.6 times its resting length and tendon at a tenth of that strain,
  /// but a spring of the network is no fibre: it also shears between fibres that slide past each
  /// other, and the tendon springs are stiffer (MuscleParameters::tendonStiffness) and stay short.
  /// Cost and what it changes: docs/decisions.md, "Strain limit".
  btScalar strainLimit = 2;
  /// Current / rest length beyond which a spring breaks at the end of a step, for good [1] (0:
  /// none; below strainLimit when both are set): the springs beyond it and the local volume terms
  /// with an edge beyond it or particles in two pieces are taken out (Tearing.h).
  btScalar breakStretch = 0;
};

/// The local volume multiple (SpringParameters::volumeStiffness) that gives the affine spring
/// network the Poisson ratio ν [1]: the springs alone have λ = μ (ν 0.25) and E = Σk·L0²/3V = 5μ,
/// a multiple V adds λ = 5V·μ, so ν = (1 + 5V)/(2(2 + 5V)) and V = (4ν − 1)/(5(1 − 2ν))
/// (docs/decisions.md, "Volume terms"); ν in [0.25, 0.5).
constexpr double volumeMultipleFor(double poissonRatio) {
  return (4 * poissonRatio - 1) / (5 * (1 - 2 * poissonRatio));
}

/// The local volume multiple `springs` ask for [1]: volumeStiffness, or when that is < 0 the one
/// of their Poisson ratio.
constexpr double volumeMultiple(const SpringParameters& springs) {
  return springs.volumeStiffness >= 0 ? double(springs.volumeStiffness)
                                      : volumeMultipleFor(springs.poissonRatio);
}

/// Bone sphere generation (method.md §6, two-ring heuristic).
struct BoneSphereParameters {
  btScalar thinning = 0;   ///< fraction of root vertices skipped at random (0..1)
  btScalar maxRadius = 0;  ///< spheres larger than this are dropped (0: no limit) [m]
};

/// The ends of a muscle that may hold no fixed particle: the origin is where its fibres start,
/// the insertion where they end.
enum class FreeEnds : uint8_t {
  None,       ///< both ends must hold a particle fixed to a bone
  Origin,     ///< the origin may be free
  Insertion,  ///< the insertion may be free
  Both,       ///< either may be free (a muscle held by contact alone, or by nothing)
};

/// Preparation of one muscle (method.md §2).
struct MuscleParameters {
  int resolution = 40;                  ///< particles per fibre
  btScalar attachmentDistance = 0.004;  ///< particles closer than this to a bone are fixed [m]
  int skinNeighbours = 3;               ///< N closest particles that move each surface vertex
  /// Length of the tendon at each attached end of a fibre, as a fraction of the fibre's rest
  /// length, measured from its last fixed particle into the free part [1] (0: no tendons, one
  /// material; a scene file's muscles default to tendons, scenes/README.md).
  btScalar tendonFraction = 0;
  /// Stiffness of a tendon spring over that of the belly spring it replaces [1] (1: none).
  /// A muscle of one material puts its strain where its section is thinnest, the converging
  /// ends; a stiffer tendon there leaves it to the belly, as in real muscle.
  btScalar tendonStiffness = 20;
  /// Ends that may hold no fixed particle; an end that holds none and is not named here is an
  /// InputError at preparation when the scene has bones (a scene file's muscles default to
  /// None).
  FreeEnds freeEnds = FreeEnds::Both;
  SpringParameters springs;  ///< spring layout and material
};

/// Time integrator by name (seed 002 §4.8.3 compares them).
enum class Integrator : uint8_t {
  Verlet,             ///< damped position Verlet, time-corrected for a varying dt (dynamics)
  SemiImplicitEuler,  ///< symplectic Euler: v += dt·a(x, v); x += dt·v
  ExplicitEuler,      ///< x += dt·v; v += dt·a(x, v)
  Rk2,                ///< midpoint Runge–Kutta, spring forces evaluated twice per iteration
  Rk4,                ///< classic Runge–Kutta, spring forces evaluated four times
  ImplicitEuler,      ///< backward Euler, one Newton step, CG on the spring Jacobian
  ImplicitMidpoint,   ///< implicit midpoint rule, one Newton step, CG
  Bdf2,               ///< second-order backward differentiation, one Newton step, CG
  Pbd,                ///< position-based dynamics: distance constraints per spring
  Xpbd,               ///< extended PBD: compliant distance constraints (compliance from κ)
  /// projective dynamics' local/global step for springs as an equilibrium solver: x += H·F
  /// with H L-BFGS's inverse Hessian started from A⁻¹, A the springs' Laplacian over the free
  /// particles plus the contacts' weights, its pattern analysed once per muscle, its factor
  /// updated (rank-one) or partly refactored when the contact set changes (default: posed scenes)
  Projective,
};

/// How muscles find bones (method.md §6; seed 002 Table 4.31).
enum class BoneCollision : uint8_t {
  Spheres,        ///< bone spheres in a static btDbvt per bone (the thesis)
  DistanceField,  ///< signed distance grid of the bone mesh in the bone frame
  /// The bone spheres find the particles near a bone; each such particle is then pushed, once per
  /// bone and iteration, until its sphere just touches the bone's true mesh (closest point +
  /// radius along the outward normal; a particle that clears the mesh is not pushed, however deep
  /// it lies in a bone sphere). A bone without a mesh pushes out of its spheres.
  Mesh,
  /// Mesh with sharp edges: a particle outside the mesh whose closest point lies on an edge or
  /// corner is pushed along the normal of the face around it whose plane it lies farthest in
  /// front of, until its sphere just touches that plane (the mesh inflated by the radius with
  /// flat faces, instead of rounded by it); from inside, or off a face, as Mesh.
  SharpMesh,
};

/// How the pre-transform of a particle between two bones (method.md §4) combines their rigid
/// motions with its blend weight w.
enum class PretransformBlend : uint8_t {
  /// The weighted sum of the two motions' displacements (linear blend skinning): a large
  /// rotation in one step pulls points towards the axis (at w = ½ and 180° onto it).
  Linear,
  /// The normalised weighted sum of the two motions as unit dual quaternions (Kavan et al.'s
  /// dual-quaternion skinning): a rigid motion for every w, which keeps the distance to a common
  /// rotation axis.
  DualQuaternion,
};

/// What the numerical guard does when a step produces NaN/inf or explodes.
enum class FailurePolicy : uint8_t {
  Retry,     ///< roll back, retry with a smaller dt up to maxRetries times, then stop the body
  StopBody,  ///< roll back and freeze the failing muscle (it stays at its last good state)
  Report,    ///< only report it in StepStats (the state is left as the step made it)
};

/// When the iterations of one step stop (method.md §4).
enum class StopRule : uint8_t {
  Iterations,       ///< a fixed number of iterations
  Converged,        ///< mean displacement below epsilon (or iteration cap reached)
  TimeBudget,       ///< wall-clock budget per step spent (or iteration cap reached)
  SpringDeviation,  ///< spring-deviation ratio Σ|l−L0| / ΣL0 below deviationEpsilon (or cap)
  /// Estimated distance to the pose's equilibrium below `tolerance` (or cap): the mean
  /// displacement d of an iteration times r/(1 − r), r the rate at which d shrank over the last
  /// 16 iterations (the remaining sum of steps of a linearly converging iteration), once r no
  /// longer slows down from one such window to the next.
  Equilibrium,
  /// The force residual's RMS equivalent displacement (ForceResidual::rmsDisplacement, the
  /// unfrozen muscles together) below `tolerance` (or cap), checked every 16 iterations once the
  /// bones arrived: a measure of the equilibrium itself, not of how fast the iteration moves.
  Residual,
};

/// The iterations per step a solver needs by default: 20 for the projective solver (thigh13
/// R=40 with no rollback and a force residual of 0.035 mm RMS; docs/performance.md, "The default
/// solver"), 70 for the time integrators (the thesis' count).
constexpr int defaultIterations(Integrator integrator) {
  return integrator == Integrator::Projective ? 20 : 70;
}

/// The most pairs MuscleSystemDef::projectiveHistory may keep [iterations].
constexpr int kMaxProjectiveHistory = 16;

/// What a step may change (method.md §4): its dt, when its iterations stop, how the bones move
/// over them; MuscleSystem::setStepSettings sets them between steps.
struct StepSettings {
  bool adaptiveTimeStep = true;  ///< eq 5.1 bound per iteration; else fixed timeStep
  btScalar timeStep = 1e-3;      ///< fixed dt, or the upper clamp of the adaptive dt [s]
  btScalar minTimeStep = 1e-5;   ///< lower clamp of the adaptive dt [s]
  StopRule stopRule = StopRule::Iterations;  ///< when a step's iterations end
  /// Iterations per step (the cap for the other rules): the default solver's default count.
  int iterations = defaultIterations(Integrator::Projective);
  btScalar epsilon = 1e-6;           ///< convergence threshold: mean displacement [m]
  btScalar budgetMs = 10;            ///< time budget per step [ms]
  btScalar deviationEpsilon = 1e-3;  ///< threshold of the spring-deviation stop rule (ratio)
  /// Equilibrium stop rule: estimated distance to it; Residual: RMS equivalent displacement [m]
  btScalar tolerance = 5e-4;
  btScalar motionFraction = 0.5;  ///< bones reach their target after this share of `iterations`
};

/// What a MuscleSystem is built with and keeps (method.md §4–§5): its threads, solver and contact
/// rules; defaultMuscleSystemDef gives one for a solver.
struct MuscleSystemDef {
  /// The solver: the projective equilibrium solver for posed scenes (each step reaches the
  /// pose's static equilibrium), Verlet or another time integrator for dynamics.
  Integrator integrator = Integrator::Projective;
  /// The settings of the steps until MuscleSystem::setStepSettings changes them.
  StepSettings stepSettings;
  bool rebuildEveryStep = false;  ///< thesis behaviour: rebuild trees and state each step
  /// Pre-transform particles of muscles spanning two bones by a blend of both bones' motions
  /// (MuscleSettings::blendBoneA/B/Weight); false: by the nearest bone only, as the thesis did
  /// (which tears such muscles apart at the boundary between the bones' regions).
  bool blendedPretransform = true;
  /// How the blended pre-transform combines the two bones' motions (docs/decisions.md,
  /// "Bone motion").
  PretransformBlend pretransformBlend = PretransformBlend::Linear;
  bool muscleMuscle = true;   ///< collide muscles with each other
  bool muscleBone = true;     ///< collide muscles with bones
  uint32_t seed = 1;          ///< seed for every random choice (jitter, thinning, noise)
  btScalar initialNoise = 0;  ///< random displacement of free particles at start [m]

  int threads = 0;  ///< worker threads of the solver (0: the machine's hardware threads)
  /// The host's task system (TaskScheduler.h); when set it runs every task of the step and
  /// `threads` is ignored (its workerCount counts the workers).
  TaskScheduler scheduler;
  /// Acceleration of gravity on every free particle [m/s²]; zero (the default, as in the thesis)
  /// adds nothing. MuscleWorld does not copy the world's gravity: set it here.
  btVector3 gravity{0, 0, 0};

  BoneCollision boneCollision = BoneCollision::Mesh;  ///< muscle–bone detection and push
  btScalar distanceFieldCell = 0.001;                 ///< cell size of bone distance fields [m]
  /// Seed 001 eq 1: a particle whose bone-distance direction flips (d·d′ < −0.75) between
  /// iterations has passed through the bone; push it back out on its previous side.
  bool penetrationRecovery = true;
  /// Response keeps a pushed particle's velocity along the contact (frictionless sliding) and
  /// removes only the part into the push; false: the thesis' x(t−dt) = x(t), which makes
  /// contacts stick (muscles sliding past each other tear, scenes/json/REAL-ANATOMY.md).
  bool slidingContacts = true;
  /// Surface contact: after the skin, a surface vertex inside a bone's true mesh moves onto its
  /// surface (the layer between the boundary spheres and the surface squashed on the bone);
  /// false: the surface is the skin alone (method.md §7).
  bool surfaceContact = true;
  /// Surface push (with BoneCollision::Mesh or SharpMesh): in each iteration's bone contact, the
  /// skinned surface vertices bound to a particle the bone spheres found near a bone that lie
  /// inside its true mesh move to the mesh's closest point, each push spread over the vertex's free
  /// skin particles by their weights; the particles' own push against the mesh then keeps only
  /// their centres out of it (radius 0). The surface, not the particles' spheres, rests on the
  /// bone: converged, pinch ends 0.78–0.86 mm from CalculiX instead of 3.2 mm (docs/decisions.md,
  /// "Bone contact"). Off by default: at the default iterations it changes little and costs more
  /// [flag].
  bool surfacePush = false;
  /// Contact damping against rigid bodies (RigidContact.h): a free particle touching a body is
  /// damped along the contact normal by this multiple of its muscle's damping coefficient c
  /// (SpringParameters::damping) on top of c, in the frame c acts in [1] (0: none; an undamped
  /// muscle has none). The springs and volume terms return most of a landing body's impact (a
  /// ball dropped on a muscle in MuscleTime::Dynamic kept 80 % of its energy and bounced off);
  /// with 4 it keeps 53 % and comes to rest (docs/contact.md).
  btScalar contactDamping = 4;

  bool diagonalJacobian = false;    ///< implicit integrators: diagonal-only Jacobian (seed 002)
  btScalar solverTolerance = 1e-6;  ///< implicit integrators: CG relative residual
  int solverIterations = 50;        ///< implicit integrators: CG iteration cap
  int constraintIterations = 4;     ///< PBD/XPBD: constraint passes per iteration (averaged Jacobi)
  /// Projective: the estimated spectral radius ρ of the plain iteration x += A⁻¹·F [1]; each
  /// step is over-relaxed by ω = 2/(1 + √(1 − ρ²)) with momentum ω − 1 (the limit of Wang 2015's
  /// Chebyshev weights); 0: the plain iteration.
  btScalar projectiveRho = 0.9;
  /// Projective: how many of the last iterations' steps and force changes shape the next step
  /// (L-BFGS with (A + W)⁻¹ as its initial inverse Hessian, Liu et al. 2017) [iterations]; 0: the
  /// over-relaxed step of projectiveRho instead. The history starts anew while bones move, when a
  /// pair shows no positive curvature and when a step does not point down the forces.
  int projectiveHistory = 5;
  /// Projective: a particle a contact pushed is held in the global step's matrix with this
  /// weight times its diagonal entry [1]. 1 lets a contact particle slide to rest sooner: with
  /// the L-BFGS step thigh13 R=40 at 5–10 iterations per pose had no rollback with 1 and 0.1 and
  /// one to four with 10 (docs/decisions.md, "Solver").
  btScalar projectiveContactWeight = 1;
  /// Projective: persistent contacts (TimeIntegrator::holdsContacts): a pushed particle's force
  /// into its push is held by the contact in the solve, and each contact is left a slop deep so
  /// that it persists; the step's fixed point is then the equilibrium with contacts. Off by
  /// default: on thigh13 R=20 it left the worst pose's residual after 10–40 iterations 1.2–1.4×
  /// higher; the `equilibrium` method turns it on (docs/decisions.md, "Solver").
  bool persistentContacts = false;
  /// Projective with persistentContacts: what a contact holds in the solve is its reaction
  /// (MuscleSystem::forceResidual's rule): equal and opposite along the pair's normal for two
  /// muscles' particles (Newton's third law), any push out of a bone, the reactions that leave the
  /// smallest residual; else each pushed particle's own force into its push (two muscles may
  /// then press into each other with unequal forces). Off: two blocks pressed together reach
  /// their equilibrium with it (test Projective.ProvesAnEquilibriumOfTwoMusclesPressedTogether),
  /// but thigh13 R=20 diverged with it at every ρ tried (docs/decisions.md, "Solver").
  bool pairReactions = false;

  FailurePolicy onFailure = FailurePolicy::Retry;  ///< numerical guard policy
  int maxRetries = 3;  ///< Retry: attempts, each with half the previous dt cap
};

/// The definition of a system that steps with `integrator`, at its default iterations per step
/// (defaultIterations); everything else at the members' defaults.
inline MuscleSystemDef defaultMuscleSystemDef(Integrator integrator = Integrator::Projective) {
  MuscleSystemDef def;
  def.integrator = integrator;
  def.stepSettings.iterations = defaultIterations(integrator);
  return def;
}

/// A setting's key in a section of a scene file (scenes/README.md says what each means): its
/// name, the values it takes and what it sets. The scene loader reads, and `--set` takes, every
/// key a visit…Settings function below lists, in its order; adding a setting's row there gives it
/// its scene key.
struct SettingKey {
  const char* name = "";  ///< the key in its section
  /// Smallest value taken [the setting's unit; metres for a length]
  double lowest = -std::numeric_limits<double>::infinity();
  /// Largest value taken [the setting's unit; metres for a length]
  double highest = std::numeric_limits<double>::infinity();
  bool lowestExcluded = false;  ///< `lowest` itself is not taken
  bool length = false;          ///< a length: written in the scene's units, kept in metres
  /// Sets how a step's iterations run and stop rather than the model they solve: a run differing
  /// from a scene only in such keys solves the scene's own model.
  bool solver = false;
  const char* trueName = nullptr;   ///< a boolean written as a name: the one for true
  const char* falseName = nullptr;  ///< a boolean written as a name: the one for false

  /// This key with `lowest` excluded.
  constexpr SettingKey open() const {
    SettingKey key = *this;
    key.lowestExcluded = true;
    return key;
  }
  /// This key as a length.
  constexpr SettingKey inMetres() const {
    SettingKey key = *this;
    key.length = true;
    return key;
  }
  /// This key as one of the solver's.
  constexpr SettingKey ofSolver() const {
    SettingKey key = *this;
    key.solver = true;
    return key;
  }
  /// This key, a boolean, written as `whenTrue` or `whenFalse`.
  constexpr SettingKey named(const char* whenTrue, const char* whenFalse) const {
    SettingKey key = *this;
    key.trueName = whenTrue;
    key.falseName = whenFalse;
    return key;
  }
};

/// Calls visit(key, member) for each setting of `def` that a scene's "simulation" section sets,
/// in the order a scene lists them, but the integrator: it comes first and sets their defaults
/// (defaultMuscleSystemDef).
template <class Visit>
void visitSimulationSettings(MuscleSystemDef& def, Visit&& visit) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  StepSettings& step = def.stepSettings;
  visit(SettingKey{"time_step"}.named("adaptive", "fixed").ofSolver(), step.adaptiveTimeStep);
  visit(SettingKey{"dt", 0, kInf}.open().ofSolver(), step.timeStep);
  visit(SettingKey{"min_dt", 0, kInf}.open().ofSolver(), step.minTimeStep);
  visit(SettingKey{"stop"}.ofSolver(), step.stopRule);
  visit(SettingKey{"iterations", 1, 100000000}.ofSolver(), step.iterations);
  visit(SettingKey{"epsilon", 0, kInf}.open().inMetres().ofSolver(), step.epsilon);
  visit(SettingKey{"budget_ms", 0, kInf}.open().ofSolver(), step.budgetMs);
  visit(SettingKey{"deviation_epsilon", 0, kInf}.open().ofSolver(), step.deviationEpsilon);
  visit(SettingKey{"tolerance", 0, kInf}.open().inMetres().ofSolver(), step.tolerance);
  visit(SettingKey{"rebuild_every_step"}, def.rebuildEveryStep);
  visit(SettingKey{"blended_pretransform"}, def.blendedPretransform);
  visit(SettingKey{"pretransform_blend"}, def.pretransformBlend);
  visit(SettingKey{"motion_fraction", 0, 1}.open().ofSolver(), step.motionFraction);
  visit(SettingKey{"seed", 0, std::numeric_limits<uint32_t>::max()}, def.seed);
  // At most 1 m: more throws particles beyond any muscle.
  visit(SettingKey{"initial_noise", 0, 1}.inMetres(), def.initialNoise);
  visit(SettingKey{"threads", 0, 1024}.ofSolver(), def.threads);
  visit(SettingKey{"diagonal_jacobian"}.ofSolver(), def.diagonalJacobian);
  visit(SettingKey{"solver_tolerance", 0, 1}.open().ofSolver(), def.solverTolerance);
  visit(SettingKey{"solver_iterations", 1, 100000}.ofSolver(), def.solverIterations);
  visit(SettingKey{"constraint_iterations", 1, 100000}.ofSolver(), def.constraintIterations);
  visit(SettingKey{"projective_rho", 0, 0.999}.ofSolver(), def.projectiveRho);
  visit(SettingKey{"projective_history", 0, kMaxProjectiveHistory}, def.projectiveHistory);
  visit(SettingKey{"projective_contact_weight", 0.01, 1e4}.ofSolver(), def.projectiveContactWeight);
  visit(SettingKey{"persistent_contacts"}, def.persistentContacts);
  visit(SettingKey{"pair_reactions"}, def.pairReactions);
  visit(SettingKey{"on_failure"}, def.onFailure);
  visit(SettingKey{"max_retries", 0, 30}, def.maxRetries);
}

/// Calls visit(key, member) for each setting of `def` that a scene's "collision" section sets,
/// in the order a scene lists them.
template <class Visit>
void visitCollisionSettings(MuscleSystemDef& def, Visit&& visit) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  visit(SettingKey{"muscle_muscle"}, def.muscleMuscle);
  visit(SettingKey{"muscle_bone"}, def.muscleBone);
  visit(SettingKey{"bone_collision"}, def.boneCollision);
  visit(SettingKey{"distance_field_cell", 0, kInf}.open().inMetres(), def.distanceFieldCell);
  visit(SettingKey{"penetration_recovery"}, def.penetrationRecovery);
  visit(SettingKey{"sliding_contacts"}, def.slidingContacts);
  visit(SettingKey{"surface_contact"}, def.surfaceContact);
  visit(SettingKey{"surface_push"}, def.surfacePush);
  visit(SettingKey{"contact_damping", 0, 1e6}, def.contactDamping);
}

const char* toString(SpringLayout layout);
const char* toString(SpringStiffness rule);
const char* toString(Integrator integrator);
const char* toString(StopRule rule);
const char* toString(BoneCollision mode);
const char* toString(FailurePolicy policy);
const char* toString(PretransformBlend blend);
/// Parse by name (as in toString); return false for an unknown name.
bool fromString(const std::string& name, SpringLayout& layout);
bool fromString(const std::string& name, SpringStiffness& rule);
bool fromString(const std::string& name, Integrator& integrator);
bool fromString(const std::string& name, StopRule& rule);
bool fromString(const std::string& name, BoneCollision& mode);
bool fromString(const std::string& name, FailurePolicy& policy);
bool fromString(const std::string& name, PretransformBlend& blend);

}  // namespace fibremss
