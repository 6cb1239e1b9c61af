#pragma once
// What report.md may claim about accuracy, internal to the comparisons library: the verdict it
// opens with, each run's error split into its model's, its solver's and its discretisation's,
// and the ranking of an analytic case by every measure of its exact answer.
#include <nlohmann/json.hpp>
#include <string>

#include "fibremss/Reference.h"

namespace fibremss {

/// The gates as summary.json holds them (referenceJson's "gates").
ReferenceGates gatesFromJson(const nlohmann::json& gates);

/// The poses a ranking by a summary's reference covers (ReferenceGates::rankedPoses).
int rankedPoses(const nlohmann::json& reference);

/// "; ranked over poses 0–5 of 19: …" (ReferenceGates::rankedPosesText) for a summary's
/// reference whose ranking covers fewer poses than the motion's; "" otherwise.
std::string rankedPosesNote(const nlohmann::json& reference);

/// Why the summary's CalculiX reference cannot rank the methods, in a few words ("" when it can:
/// it is there and every gate passed): none in the summary, not in the cache, or
/// ReferenceGates::whyNotPassed.
std::string whyNoReferenceRanking(const nlohmann::json& summary);

/// Whether the run solves the model the `equilibrium` run converged: the self-reference, the
/// equilibrium run, `fibremss` and its variants that change solver settings only.
bool solvesEquilibriumModel(const nlohmann::json& run);

/// The section report.md opens with: which run is the most accurate and which runs are the most
/// accurate per millisecond (no other run both faster and at least as accurate), against the
/// exact answer of an analytic case and against the CalculiX reference where every gate passed;
/// otherwise plainly that nothing is ranked, and why.
std::string verdictSection(const nlohmann::json& summary);

/// A markdown section: per run, its distance to the reference, its model's converged state's
/// (the `equilibrium` run's) distance to the reference, its distance to that converged state,
/// and one level finer's move of it; "—" and why where a term is not available.
std::string errorDecomposition(const nlohmann::json& summary);

/// On an analytic case, the ranking by the exact answer (no reference, so no gate): each method
/// family's best run by its worst place over the case's measures (stretch: effective ν and
/// volume; twist: section profile, mid radius and volume). Empty for other scenes.
std::string exactRanking(const nlohmann::json& runs);

}  // namespace fibremss
