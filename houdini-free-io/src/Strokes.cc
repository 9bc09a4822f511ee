#include <turbio/Strokes.h>

#include <turb/Error.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <regex>
#include <sstream>

namespace turbio {

namespace {

/// The line (1-based) on which each object of the top-level array `key` ("strokes", "clones") starts. A small scanner
/// over the raw text: nlohmann's parser keeps no positions for values.
std::vector<int> strokeLines(const std::string& text, const std::string& key = "strokes")
{
    std::vector<int> lines;
    std::vector<char> stack; // open containers
    std::string lastKey;     // the last string seen as a key of the top-level object
    bool inStrokes = false;  // inside the top-level "strokes" array
    int line = 1;
    for (size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (c == '\n') {
            ++line;
        } else if (c == '"') {
            std::string s;
            for (++i; i < text.size() && text[i] != '"'; ++i) {
                if (text[i] == '\\') ++i;
                else if (text[i] == '\n') ++line;
                else s += text[i];
            }
            if (stack.size() == 1 && stack.back() == '{') lastKey = s;
        } else if (c == '{' || c == '[') {
            if (c == '{' && inStrokes && stack.size() == 2) lines.push_back(line);
            if (c == '[' && stack.size() == 1 && lastKey == key) inStrokes = true;
            stack.push_back(c);
        } else if (c == '}' || c == ']') {
            if (!stack.empty()) stack.pop_back();
            if (c == ']' && stack.size() == 1) inStrokes = false;
        }
    }
    return lines;
}

[[noreturn]] void fail(const std::string& name, int line, const std::string& what)
{
    throw turb::IoError(name + (line > 0 ? ":" + std::to_string(line) : "") + ": " + what);
}

double number(const nlohmann::json& j, const char* key, const std::string& name, int line, const std::string& who)
{
    if (!j.contains(key)) fail(name, line, who + ": missing \"" + key + "\"");
    if (!j.at(key).is_number()) fail(name, line, who + ": \"" + key + "\" must be a number");
    return j.at(key).get<double>();
}

// The document, with nlohmann's parse errors worded as "name:3: column 5: malformed JSON: ...".
nlohmann::json parseDocument(const std::string& text, const std::string& name)
{
    nlohmann::json doc;
    try {
        doc = nlohmann::json::parse(text);
    } catch (const nlohmann::json::parse_error& e) {
        // "[json.exception.parse_error.101] parse error at line 3, column 5: ..." -> "name:3: column 5: ..."
        std::string msg = e.what();
        std::smatch m;
        if (std::regex_search(msg, m, std::regex("at line ([0-9]+), column ([0-9]+): (.*)")))
            fail(name, std::stoi(m[1]), "column " + std::string(m[2]) + ": malformed JSON: " + std::string(m[3]));
        fail(name, 0, "malformed JSON: " + msg);
    }
    return doc;
}

/// One stroke of the file, in pixels of the width x height frame (canvas coordinates times sx, sy), checked alone.
turb::FlowStroke parseStroke(const nlohmann::json& j, const std::string& name, int line, const std::string& who,
    double sx, double sy, int width, int height)
{
    if (!j.is_object()) fail(name, line, who + ": expected an object");
    turb::FlowStroke s;
    const std::string brush = j.value("brush", std::string());
    if (brush == "orientation") s.kind = turb::StrokeKind::Orientation;
    else if (brush == "speed") s.kind = turb::StrokeKind::Speed;
    else fail(name, line, who + ": \"brush\" must be \"orientation\" or \"speed\"");
    const std::string mode = j.contains("mode") && j["mode"].is_string() ? j["mode"].get<std::string>() : "global";
    if (mode != "global" && mode != "local") fail(name, line, who + ": \"mode\" must be \"global\" or \"local\"");
    s.local = mode == "local";
    if (s.local) {
        s.size = number(j, "size", name, line, who) * std::sqrt(sx * sy);
        s.alpha = j.contains("alpha") ? number(j, "alpha", name, line, who) : 1.0;
        if (!(s.size > 0.0)) fail(name, line, who + ": \"size\" must be > 0 pixels");
        if (!(s.alpha >= 0.0 && s.alpha <= 1.0)) fail(name, line, who + ": \"alpha\" must be in [0, 1]");
    }
    if (s.kind == turb::StrokeKind::Speed) {
        if (j.contains("speed") && j["speed"].is_string() && j["speed"].get<std::string>() == "example") {
            s.exampleSpeed = true;
        } else {
            s.speed = number(j, "speed", name, line, who);
            if (!(s.speed >= 0.0)) fail(name, line, who + ": \"speed\" must be >= 0 pixels per frame (or \"example\")");
        }
    }
    if (!j.contains("points") || !j["points"].is_array()) fail(name, line, who + ": missing the \"points\" array");
    for (const auto& p : j["points"]) {
        if (!p.is_array() || p.size() != 2 || !p[0].is_number() || !p[1].is_number())
            fail(name, line, who + ": every point must be [x, y]");
        s.points.push_back({p[0].get<double>() * sx, p[1].get<double>() * sy});
    }
    try {
        // One stroke alone, plus a dummy global orientation stroke so the set rule does not fire here.
        turb::FlowStroke dummy;
        dummy.points = {{0.0, 0.0}, {1.0, 0.0}};
        const std::vector<turb::FlowStroke> one{s, dummy};
        turb::validateStrokes(one, width, height);
    } catch (const turb::ValueError& e) {
        std::string m = e.what();
        const std::string prefix = "stroke 0 ";
        if (m.rfind(prefix, 0) == 0) m = who + " " + m.substr(prefix.size());
        fail(name, line, m + (sx != 1.0 || sy != 1.0 ? " (after scaling from the canvas)" : ""));
    }
    return s;
}

/// A canvas's scale to an image of width x height: "canvas": [w, h] -> (width / w, height / h); (1, 1) without one.
std::pair<double, double> canvasScale(
    const nlohmann::json& doc, const char* key, const std::string& name, int width, int height)
{
    if (!doc.contains(key)) return {1.0, 1.0};
    const auto& c = doc[key];
    if (!c.is_array() || c.size() != 2 || !c[0].is_number() || !c[1].is_number() || !(c[0].get<double>() > 0) ||
        !(c[1].get<double>() > 0))
        fail(name, 0, "\"" + std::string(key) + "\" must be [width, height] in pixels");
    return {double(width) / c[0].get<double>(), double(height) / c[1].get<double>()};
}

std::vector<turb::StrokePoint> points(const nlohmann::json& j, const char* key, const std::string& name, int line,
    const std::string& who, std::pair<double, double> scale = {1.0, 1.0})
{
    if (!j.contains(key) || !j[key].is_array()) fail(name, line, who + ": missing the \"" + key + "\" array");
    std::vector<turb::StrokePoint> out;
    for (const auto& p : j[key]) {
        if (!p.is_array() || p.size() != 2 || !p[0].is_number() || !p[1].is_number())
            fail(name, line, who + ": every point of \"" + key + "\" must be [x, y]");
        out.push_back({p[0].get<double>() * scale.first, p[1].get<double>() * scale.second});
    }
    return out;
}

/// The sizes a clone file's points are read against, and the canvases' scales to them.
struct CloneFrame
{
    int EW, EH, TW, TH;
    std::pair<double, double> source{1.0, 1.0}, destination{1.0, 1.0};
};

// One clone pair of the file, checked alone (the library's words, with the file's line).
turb::CloneStroke parseClone(const nlohmann::json& j, const std::string& name, int line, size_t k, const CloneFrame& f)
{
    const std::string who = "clone stroke " + std::to_string(k);
    if (!j.is_object()) fail(name, line, who + ": expected an object");
    turb::CloneStroke c;
    c.source = points(j, "source", name, line, who, f.source);
    c.destination = points(j, "destination", name, line, who, f.destination);
    c.size = number(j, "size", name, line, who) * std::sqrt(f.destination.first * f.destination.second);
    if (j.contains("alpha")) c.alpha = number(j, "alpha", name, line, who);
    try {
        turb::validateCloneStrokes({c}, f.EW, f.EH, f.TW, f.TH);
    } catch (const turb::ValueError& e) {
        std::string m = e.what();
        const std::string prefix = "clone stroke 0";
        if (m.rfind(prefix, 0) == 0) m = who + m.substr(prefix.size());
        const bool scaled = f.source != std::make_pair(1.0, 1.0) || f.destination != std::make_pair(1.0, 1.0);
        fail(name, line, m + (scaled ? " (after scaling from the canvas)" : ""));
    }
    return c;
}

} // namespace

CloneFile parseCloneStrokes(const std::string& text, const std::string& name, int EW, int EH, int TW, int TH)
{
    const nlohmann::json doc = parseDocument(text, name);
    if (!doc.is_object()) fail(name, 1, "expected a JSON object with \"clones\"");
    if (doc.contains("version") && (!doc["version"].is_number_integer() || doc["version"].get<int>() != 1))
        fail(name, 0, "unsupported \"version\" (this reader knows 1)");
    if (!doc.contains("clones") || !doc["clones"].is_array()) fail(name, 0, "missing the \"clones\" array");
    CloneFrame frame{EW, EH, TW, TH};
    frame.source = canvasScale(doc, "example_canvas", name, EW, EH);
    frame.destination = canvasScale(doc, "canvas", name, TW, TH);
    const std::vector<int> lines = strokeLines(text, "clones");
    CloneFile out;
    const auto& arr = doc["clones"];
    for (size_t k = 0; k < arr.size(); ++k) {
        const int line = k < lines.size() ? lines[k] : 0;
        out.clones.push_back(parseClone(arr[k], name, line, k, frame));
        out.lines.push_back(line);
    }
    return out;
}

CloneFile readCloneStrokes(const std::string& path, int EW, int EH, int TW, int TH)
{
    std::ifstream in(path);
    if (!in) throw turb::IoError(path + ": cannot open the clone stroke file");
    std::stringstream ss;
    ss << in.rdbuf();
    return parseCloneStrokes(ss.str(), path, EW, EH, TW, TH);
}

StrokeFile parseFlowStrokes(const std::string& text, const std::string& name, int width, int height)
{
    nlohmann::json doc = parseDocument(text, name);
    if (!doc.is_object()) fail(name, 1, "expected a JSON object with \"strokes\"");
    if (doc.contains("version") && (!doc["version"].is_number_integer() || doc["version"].get<int>() != 1))
        fail(name, 0, "unsupported \"version\" (this reader knows 1)");
    if (!doc.contains("strokes") || !doc["strokes"].is_array()) fail(name, 0, "missing the \"strokes\" array");
    double sx = 1.0, sy = 1.0;
    if (doc.contains("canvas")) {
        const auto& c = doc["canvas"];
        if (!c.is_array() || c.size() != 2 || !c[0].is_number() || !c[1].is_number() || !(c[0].get<double>() > 0) ||
            !(c[1].get<double>() > 0))
            fail(name, 0, "\"canvas\" must be [width, height] in pixels");
        sx = double(width) / c[0].get<double>();
        sy = double(height) / c[1].get<double>();
    }
    const std::vector<int> lines = strokeLines(text);
    StrokeFile out;
    const auto& arr = doc["strokes"];
    for (size_t k = 0; k < arr.size(); ++k) {
        const int line = k < lines.size() ? lines[k] : 0;
        out.strokes.push_back(parseStroke(arr[k], name, line, "stroke " + std::to_string(k), sx, sy, width, height));
        out.lines.push_back(line);
    }
    try {
        turb::validateStrokes(out.strokes, width, height);
    } catch (const turb::ValueError& e) {
        fail(name, 0, e.what());
    }
    return out;
}

StrokeFile readFlowStrokes(const std::string& path, int width, int height)
{
    std::ifstream in(path);
    if (!in) throw turb::IoError(path + ": cannot open the stroke file");
    std::stringstream ss;
    ss << in.rdbuf();
    return parseFlowStrokes(ss.str(), path, width, height);
}

} // namespace turbio
