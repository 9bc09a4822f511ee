/// @file Validators.h
/// @brief Checks of option values that every command shares (CLI11 validators and the NaN check after parsing).
///        A leaf of tools/: it includes no other header of tools/, so Console and the commands can both use it.
#pragma once

#include <turb/run/Flags.h>

#include <CLI/CLI.hpp>

#include <functional>
#include <string>

namespace vdbturb {

/// A CLI check that runs `parse` on the option's text when the command line is parsed, so text it throws on is a
/// usage error (exit 2) with its message, like any other malformed option. `name` is the type shown in --help.
CLI::Validator parsedBy(std::function<void(const std::string&)> parse, const std::string& name);

/// Checks a frame list ("1001-1100x2,1200") when the command line is parsed, so a bad one is a usage error
/// (exit 2) naming the bad piece, like any other malformed option.
CLI::Validator frameListCheck();

using turb::run::parseNumber;
/// A CLI check for a finite number in [lo, hi] (CLI11's own number checks let NaN through).
CLI::Validator finiteIn(double lo, double hi = 1e30);
/// A transform that turns a ratio "N/D" (24000/1001) into its value, for a range check after it.
CLI::Validator rationalNumber();
/// A finite number > 0 (CLI11's PositiveNumber lets NaN through and prints DBL_MAX in full in its message).
CLI::Validator finitePositive();

/// CLI11's range checks let NaN through: the first option of `app` or its subcommands whose number is NaN, as
/// "--NAME: nan is not a number"; empty when there is none.
std::string notANumber(const CLI::App& app);

} // namespace vdbturb
