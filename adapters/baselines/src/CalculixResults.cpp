// CalculiX's printed results (.dat): the tables *NODE PRINT writes, read back.
#include <cmath>
#include <cstdlib>
#include <istream>
#include <sstream>

#include "fibremss/Calculix.h"
#include "fibremss/Error.h"

namespace fibremss {
namespace {

/// Parses a table heading "<quantity> (<components>) for set <SET> and time <T>"; false when
/// the line is not one.
bool parseHeading(const std::string& line, CalculixTable& table) {
  const size_t open = line.find(" (");
  const size_t forSet = line.find(") for set ");
  const size_t andTime = line.find(" and time ");
  if (open == std::string::npos || forSet == std::string::npos || andTime == std::string::npos ||
      !(open < forSet && forSet < andTime)) {
    return false;
  }
  const size_t first = line.find_first_not_of(' ');
  table.quantity = line.substr(first, open - first);
  table.set = line.substr(forSet + 10, andTime - forSet - 10);
  std::istringstream time(line.substr(andTime + 10));
  return static_cast<bool>(time >> table.time);
}

/// Splits a row into numbers; false when some field is not a number.
bool parseRow(const std::string& line, std::vector<double>& numbers) {
  numbers.clear();
  std::istringstream fields(line);
  std::string field;
  while (fields >> field) {
    char* end = nullptr;
    const double value = std::strtod(field.c_str(), &end);
    if (end == field.c_str() || *end != '\0') return false;
    numbers.push_back(value);
  }
  return true;
}

/// Adds a row to `table`: with a node number when it holds one more number than a totals row.
void addRow(CalculixTable& table, const std::vector<double>& numbers, bool totals) {
  const size_t skip = totals ? 0 : 1;
  if (!totals) table.ids.push_back(static_cast<int>(numbers[0]));
  if (table.components == 0) table.components = static_cast<int>(numbers.size() - skip);
  table.values.insert(table.values.end(), numbers.begin() + static_cast<long>(skip), numbers.end());
}

}  // namespace

std::vector<CalculixTable> readCalculixDat(std::istream& in, const std::string& source) {
  std::vector<CalculixTable> tables;
  std::string line;
  std::vector<double> numbers;
  int lineNumber = 0;
  while (std::getline(in, line)) {
    ++lineNumber;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    CalculixTable heading;
    if (parseHeading(line, heading)) {
      tables.push_back(std::move(heading));
      continue;
    }
    if (tables.empty()) continue;  // text before the first table (none is printed today)
    CalculixTable& table = tables.back();
    if (!parseRow(line, numbers) || numbers.empty()) {
      throw InputError(
          source, "line " + std::to_string(lineNumber),
          "expected a row of numbers of table '" + table.quantity + "', got '" + line + "'");
    }
    const bool totals = table.quantity.rfind("total", 0) == 0;
    const size_t expected = static_cast<size_t>(table.components) + (totals ? 0 : 1);
    if (table.components > 0 && numbers.size() != expected) {
      throw InputError(source, "line " + std::to_string(lineNumber),
                       "expected " + std::to_string(expected) + " numbers, got " +
                           std::to_string(numbers.size()));
    }
    addRow(table, numbers, totals);
  }
  return tables;
}

std::vector<const CalculixTable*> stepEndTables(const std::vector<CalculixTable>& tables,
                                                const std::string& quantity, const std::string& set,
                                                int steps) {
  std::vector<const CalculixTable*> ends;
  for (int step = 1; step <= steps; ++step) {
    const CalculixTable* found = nullptr;
    for (const CalculixTable& table : tables) {
      if (table.quantity == quantity && table.set == set && std::abs(table.time - step) < 1e-6)
        found = &table;
    }
    if (!found) break;
    ends.push_back(found);
  }
  return ends;
}

}  // namespace fibremss
