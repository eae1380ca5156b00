#include "inekf_semantic_mapping/kitti/timestamps.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>

#include "inekf_semantic_mapping/kitti/errors.h"
#include "text_parsing.h"

namespace inekf_semantic_mapping {
namespace kitti {
namespace {

// Howard Hinnant's days_from_civil: days since 1970-01-01 of a proleptic Gregorian date.
std::int64_t daysFromCivil(std::int64_t year, unsigned month, unsigned day) {
  year -= month <= 2;
  const std::int64_t era = (year >= 0 ? year : year - 399) / 400;
  const unsigned year_of_era = static_cast<unsigned>(year - era * 400);
  const unsigned day_of_year = (153 * (month + (month > 2 ? -3 : 9)) + 2) / 5 + day - 1;
  const unsigned day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
  return era * 146097 + static_cast<std::int64_t>(day_of_era) - 719468;
}

// Its inverse: the proleptic Gregorian date of a day count since 1970-01-01.
void civilFromDays(std::int64_t z, std::int64_t* year, unsigned* month, unsigned* day) {
  z += 719468;
  const std::int64_t era = (z >= 0 ? z : z - 146096) / 146097;
  const unsigned day_of_era = static_cast<unsigned>(z - era * 146097);
  const unsigned year_of_era =
      (day_of_era - day_of_era / 1460 + day_of_era / 36524 - day_of_era / 146096) / 365;
  const unsigned day_of_year =
      day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
  const unsigned mp = (5 * day_of_year + 2) / 153;
  *day = day_of_year - (153 * mp + 2) / 5 + 1;
  *month = mp < 10 ? mp + 3 : mp - 9;
  *year = static_cast<std::int64_t>(year_of_era) + era * 400 + (*month <= 2);
}

// Reads exactly `digits` decimal digits at text[*pos].
bool readDigits(const std::string& text, std::size_t* pos, int digits, int* value) {
  *value = 0;
  for (int i = 0; i < digits; ++i, ++*pos) {
    if (*pos >= text.size() || !std::isdigit(static_cast<unsigned char>(text[*pos]))) return false;
    *value = *value * 10 + (text[*pos] - '0');
  }
  return true;
}

bool expectChar(const std::string& text, std::size_t* pos, char c) {
  if (*pos >= text.size() || text[*pos] != c) return false;
  ++*pos;
  return true;
}

}  // namespace

std::int64_t parseKittiTimestampNs(const std::string& raw_text) {
  const std::string text = detail::trim(raw_text);
  auto fail = [&](const std::string& why) {
    return KittiFormatError("<timestamp '" + text + "'>",
                            why + " (expected YYYY-MM-DD HH:MM:SS[.fraction])");
  };
  std::size_t pos = 0;
  int year, month, day, hour, minute, second;
  if (!readDigits(text, &pos, 4, &year) || !expectChar(text, &pos, '-') ||
      !readDigits(text, &pos, 2, &month) || !expectChar(text, &pos, '-') ||
      !readDigits(text, &pos, 2, &day) || !expectChar(text, &pos, ' ') ||
      !readDigits(text, &pos, 2, &hour) || !expectChar(text, &pos, ':') ||
      !readDigits(text, &pos, 2, &minute) || !expectChar(text, &pos, ':') ||
      !readDigits(text, &pos, 2, &second)) {
    throw fail("malformed date/time");
  }
  if (month < 1 || month > 12 || day < 1 || hour > 23 || minute > 59 || second > 60) {
    throw fail("date/time field out of range");
  }
  static constexpr int kDaysInMonth[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  const bool leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
  if (day > kDaysInMonth[month - 1] + (month == 2 && leap ? 1 : 0)) {
    throw fail("day " + std::to_string(day) + " does not exist in month " + std::to_string(month));
  }
  // Nanoseconds since 1970 in an int64 reach from 1677 to 2262.
  if (year < 1678 || year > 2261) throw fail("year outside 1678..2261");
  std::int64_t fraction_ns = 0;
  if (pos < text.size()) {
    if (!expectChar(text, &pos, '.')) throw fail("unexpected character after seconds");
    int digits = 0;
    while (pos < text.size()) {
      const char c = text[pos++];
      if (!std::isdigit(static_cast<unsigned char>(c))) throw fail("non-digit in the fraction");
      if (++digits > 9) throw fail("more than 9 fraction digits");
      fraction_ns = fraction_ns * 10 + (c - '0');
    }
    if (digits == 0) throw fail("empty fraction");
    for (int i = digits; i < 9; ++i) fraction_ns *= 10;
  }
  const std::int64_t days =
      daysFromCivil(year, static_cast<unsigned>(month), static_cast<unsigned>(day));
  const std::int64_t seconds = days * 86400 + hour * 3600 + minute * 60 + second;
  return seconds * 1000000000LL + fraction_ns;
}

std::vector<bool> isolatedMisstampedFrames(const std::vector<std::int64_t>& stamps_ns,
                                           double max_gap_s, std::size_t max_run) {
  const std::size_t n = stamps_ns.size();
  std::vector<bool> misstamped(n, false);
  const auto far = [max_gap_s](std::int64_t a, std::int64_t b) {
    return std::abs(secondsBetween(a, b)) > max_gap_s;
  };
  std::size_t i = 1;
  while (i + 1 < n) {
    const std::int64_t before = stamps_ns[i - 1];
    // The run i..last: every stamp in it far from `before`; it ends where a frame comes back in
    // order within max_gap_s of `before` and far from each stamp of the run.
    std::size_t last = i;
    bool found = false;
    while (last + 1 < n && last - i < max_run && far(before, stamps_ns[last])) {
      const std::int64_t after = stamps_ns[last + 1];
      if (after > before && !far(before, after)) {
        found = true;
        for (std::size_t k = i; k <= last && found; ++k) found = far(stamps_ns[k], after);
        break;
      }
      ++last;
    }
    if (found) {
      for (std::size_t k = i; k <= last; ++k) misstamped[k] = true;
      i = last + 2;  // the frame after the run is in order: the next run starts after it
    } else {
      ++i;
    }
  }
  return misstamped;
}

std::vector<std::string> timestampWarnings(const std::vector<std::int64_t>& stamps_ns,
                                           const std::string& path, double max_gap_s,
                                           std::size_t max_messages,
                                           const std::vector<std::size_t>& lines) {
  if (!lines.empty() && lines.size() != stamps_ns.size()) {
    throw std::invalid_argument("timestampWarnings: " + std::to_string(lines.size()) +
                                " line numbers for " + std::to_string(stamps_ns.size()) +
                                " stamps");
  }
  const auto line_of = [&lines](std::size_t i) { return (lines.empty() ? i : lines[i]) + 1; };
  std::vector<std::string> warnings;
  std::size_t more = 0;
  for (std::size_t i = 1; i < stamps_ns.size(); ++i) {
    const double step_s = secondsBetween(stamps_ns[i - 1], stamps_ns[i]);
    // A repeated stamp is a message the consumers drop as out of order: worth a line too.
    if (stamps_ns[i] > stamps_ns[i - 1] && step_s <= max_gap_s) continue;
    if (warnings.size() == max_messages) {
      ++more;
      continue;
    }
    const std::string earlier = line_of(i - 1) + 1 == line_of(i)
                                    ? std::string("the line above")
                                    : "line " + std::to_string(line_of(i - 1));
    char text[96];
    if (stamps_ns[i] == stamps_ns[i - 1]) {
      std::snprintf(text, sizeof(text), ":%zu: the same stamp as ", line_of(i));
    } else {
      std::snprintf(text, sizeof(text), ":%zu: %.3f s %s ", line_of(i), std::abs(step_s),
                    step_s < 0.0 ? "before" : "after");
    }
    warnings.push_back(path + text + earlier);
  }
  if (more > 0) {
    warnings.push_back(path + ": " + std::to_string(more) + " more such steps");
  }
  return warnings;
}

std::vector<std::optional<std::int64_t>> readTimestampLines(const std::string& path) {
  std::ifstream stream = detail::openOrThrow(path);
  std::vector<std::optional<std::int64_t>> stamps;
  std::string line;
  int line_number = 0;
  while (std::getline(stream, line)) {
    ++line_number;
    if (detail::trim(line).empty()) {
      stamps.emplace_back();
      continue;
    }
    try {
      stamps.emplace_back(parseKittiTimestampNs(line));
    } catch (const KittiFormatError& error) {
      throw KittiFormatError(path, line_number, error.what());
    }
  }
  while (!stamps.empty() && !stamps.back()) stamps.pop_back();
  return stamps;
}

std::string formatKittiTimestamp(std::int64_t stamp_ns) {
  constexpr std::int64_t kNsPerDay = 86400LL * 1000000000LL;
  std::int64_t days = stamp_ns / kNsPerDay;
  std::int64_t rest = stamp_ns % kNsPerDay;
  if (rest < 0) {
    rest += kNsPerDay;
    --days;
  }
  std::int64_t year;
  unsigned month, day;
  civilFromDays(days, &year, &month, &day);
  const std::int64_t seconds = rest / 1000000000LL;
  char text[64];
  std::snprintf(text, sizeof(text), "%04lld-%02u-%02u %02lld:%02lld:%02lld.%09lld",
                static_cast<long long>(year), month, day, static_cast<long long>(seconds / 3600),
                static_cast<long long>(seconds / 60 % 60), static_cast<long long>(seconds % 60),
                static_cast<long long>(rest % 1000000000LL));
  return text;
}

}  // namespace kitti
}  // namespace inekf_semantic_mapping
