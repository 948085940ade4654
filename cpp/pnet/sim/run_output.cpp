#include "pnet/sim/run_output.hpp"

#include <cstdio>
#include <sstream>
#include <stdexcept>
#include <type_traits>

namespace pnet {

namespace {

/// One CSV cell: integers and counts in full, booleans as 0/1, doubles with `format`.
template <typename T>
void append_cell(std::string& row, T value, const char* format) {
    char cell[64];
    if constexpr (std::is_same_v<T, bool>)
        std::snprintf(cell, sizeof cell, "%d", value ? 1 : 0);
    else if constexpr (std::is_floating_point_v<T>)
        std::snprintf(cell, sizeof cell, format, value);
    else if constexpr (std::is_signed_v<T>)
        std::snprintf(cell, sizeof cell, "%lld", static_cast<long long>(value));
    else
        std::snprintf(cell, sizeof cell, "%llu", static_cast<unsigned long long>(value));
    if (!row.empty()) row += ',';
    row += cell;
}

bool shown(const FrameField& field, const RunColumns& columns) {
    return field.column && (!field.fem || columns.fem) && (!field.three_d || columns.dim == 3);
}

bool shown(const StepField& field, const RunColumns& columns) {
    return field.column && (!field.fem || columns.fem);
}

}  // namespace

std::string stats_csv_header(const RunColumns& columns) {
    std::string header;
    for_each_frame_field([&](const FrameField& field, auto) {
        if (!shown(field, columns)) return;
        if (!header.empty()) header += ',';
        header += field.column;
    });
    return header + "\n";
}

std::string stats_csv_row(const FrameStats& frame, const RunColumns& columns) {
    std::string row;
    for_each_frame_field([&](const FrameField& field, auto get) {
        if (shown(field, columns)) append_cell(row, get(frame), field.format);
    });
    return row + "\n";
}

std::string steps_csv_header(const RunColumns& columns) {
    std::string header = "frame,step,time_s";
    for_each_step_field([&](const StepField& field, auto) {
        if (shown(field, columns)) header += std::string(",") + field.column;
    });
    return header + ",integrator\n";
}

std::string steps_csv_row(int frame, long step, double time, const StepRecord& stats, const RunColumns& columns) {
    std::string row;
    append_cell(row, frame, "");
    append_cell(row, step, "");
    append_cell(row, time, "%.9g");
    for_each_step_field([&](const StepField& field, auto member) {
        if (shown(field, columns)) append_cell(row, stats.*member, field.format);
    });
    return row + "," + columns.integrator + "\n";
}

std::vector<std::string> csv_column(const std::string& csv, const std::string& name) {
    std::istringstream lines(csv);
    std::string line;
    auto cells = [](const std::string& text) {
        std::vector<std::string> out;
        std::stringstream fields(text);
        for (std::string cell; std::getline(fields, cell, ',');) out.push_back(cell);
        return out;
    };
    std::getline(lines, line);
    const std::vector<std::string> header = cells(line);
    std::size_t index = header.size();
    for (std::size_t k = 0; k < header.size(); ++k)
        if (header[k] == name) index = k;
    if (index == header.size()) throw std::invalid_argument("CSV: no column '" + name + "'");
    std::vector<std::string> values;
    while (std::getline(lines, line)) {
        if (line.empty()) continue;
        const std::vector<std::string> row = cells(line);
        if (row.size() <= index) throw std::invalid_argument("CSV: a row has no column '" + name + "': " + line);
        values.push_back(row[index]);
    }
    return values;
}

}  // namespace pnet
