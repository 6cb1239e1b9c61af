#pragma once
// Tearing (MuscleSettings::breakStretch, internal): after each kept step, a muscle's springs
// stretched beyond breakStretch times their rest length break for good, and with them the local
// volume terms that have an edge beyond it or particles in two pieces; the pieces are the
// components of the unbroken springs. Sequential per muscle, in the muscles' order, with no
// allocation: the same bits for every thread count.
namespace fibremss {

struct MuscleState;

/// Gives `muscle` its own copy of its settings and the scratch of its pieces when its settings
/// tear (breakStretch > 0); counts its pieces at rest.
void prepareTearing(MuscleState& muscle);

/// Breaks the springs and volume terms of a tearing `muscle` beyond its breakStretch at its
/// positions, then the volume terms across pieces; recounts its pieces when something broke.
/// Returns whether something broke (the integrator's workspace must then follow).
bool breakStretched(MuscleState& muscle);

/// Whether a piece of `muscle` has grown beyond `factor` times its rest extent (bounding-box
/// diagonal); a muscle in one piece as a whole.
bool piecesSpread(MuscleState& muscle, double factor);

}  // namespace fibremss
