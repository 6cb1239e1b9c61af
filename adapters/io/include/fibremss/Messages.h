#pragma once
// How FibreMSS's tools tell the user about something that is not an error: one prefix for every
// subcommand, always on stderr (stdout carries the results, which a script may parse).
#include <span>
#include <string>
#include <string_view>

namespace fibremss {

/// "fibremss: warning: TEXT" (for a caller that prints through its own log, e.g. between
/// progress bars).
std::string warningLine(std::string_view text);
/// "fibremss: note: TEXT".
std::string noteLine(std::string_view text);
/// Prints warningLine(text) and a line break on stderr.
void printWarning(std::string_view text);
/// Prints noteLine(text) and a line break on stderr.
void printNote(std::string_view text);
/// printWarning for each text, in order.
void printWarnings(std::span<const std::string> texts);
/// printNote for each text, in order.
void printNotes(std::span<const std::string> texts);

}  // namespace fibremss
