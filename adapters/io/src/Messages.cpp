#include "fibremss/Messages.h"

#include <cstdio>

namespace fibremss {
std::string warningLine(std::string_view text) {
  return "fibremss: warning: " + std::string(text);
}

std::string noteLine(std::string_view text) {
  return "fibremss: note: " + std::string(text);
}

void printWarning(std::string_view text) {
  std::fprintf(stderr, "%s\n", warningLine(text).c_str());
}

void printNote(std::string_view text) {
  std::fprintf(stderr, "%s\n", noteLine(text).c_str());
}

void printWarnings(std::span<const std::string> texts) {
  for (const std::string& text : texts) printWarning(text);
}

void printNotes(std::span<const std::string> texts) {
  for (const std::string& text : texts) printNote(text);
}

}  // namespace fibremss
