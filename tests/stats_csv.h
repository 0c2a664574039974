// A run's stats.csv (one row per frame, job/stats_file.h) as numbers, for
// tests that look at what the frames measured.
#pragma once

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace collido::test {

struct StatsCsv {
  std::vector<std::string> names;         // the header's columns
  std::vector<std::vector<double>> rows;  // a frame each, in order
  // The column's place in a row; names.size() where there is none.
  size_t column(const std::string& name) const {
    return size_t(std::find(names.begin(), names.end(), name) - names.begin());
  }
};

// DIR/stats.csv; empty when it cannot be read.
inline StatsCsv read_stats_csv(const std::string& dir) {
  StatsCsv s;
  std::ifstream in(dir + "/stats.csv");
  std::string line, cell;
  if (!std::getline(in, line)) return s;
  for (std::stringstream h(line); std::getline(h, cell, ',');) s.names.push_back(cell);
  while (std::getline(in, line)) {
    std::vector<double> row;
    for (std::stringstream r(line); std::getline(r, cell, ',');) row.push_back(std::stod(cell));
    s.rows.push_back(std::move(row));
  }
  return s;
}

}  // namespace collido::test
