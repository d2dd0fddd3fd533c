// "Did you mean ...?" for a misspelt configuration key or command-line option: the candidate
// nearest by edit distance, if it is near enough to be a slip rather than another word.
#pragma once

#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace pandarcap {

// Levenshtein distance (insertions, deletions, substitutions; a swap of neighbours counts 1).
std::size_t edit_distance(std::string_view a, std::string_view b);

// The candidate nearest `word`, when its distance is at most a third of the word's length
// (at least 1, at most 3); ties go to the first. Nothing when none is that near.
std::optional<std::string> nearest(std::string_view word,
                                   std::span<const std::string_view> candidates);

}  // namespace pandarcap
