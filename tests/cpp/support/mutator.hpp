#pragma once
// Deterministic input mutations for the fuzz tests (tests/cpp/fuzz, the model loader's): byte-level
// damage (truncation, bit flips, interesting bytes, inserted, deleted and duplicated runs) and, for
// JSON documents, structural damage (type swaps, huge numbers, removed keys, deep nesting).
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <iterator>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

namespace pnet::test {

/// Cases per loader: PNET_FUZZ_CASES if set (more on demand), else the suite's default.
inline int fuzz_cases(int suite_default) {
    if (const char* env = std::getenv("PNET_FUZZ_CASES")) return std::max(1, std::atoi(env));
    return suite_default;
}

/// Deterministic mutations of a byte string or a JSON document.
class Mutator {
public:
    explicit Mutator(std::uint64_t seed) : rng_(seed) {}

    int below(int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng_); }

    std::string bytes(std::string s) {
        const int rounds = 1 + below(3);
        for (int r = 0; r < rounds && !s.empty(); ++r) {
            const std::size_t at = std::size_t(below(int(s.size())));
            switch (below(6)) {
                case 0: s.resize(at); break;                                        // truncation
                case 1: s[at] = char(s[at] ^ (1 << below(8))); break;                 // bit flip
                case 2: s[at] = char("\x00\xff\x7f\x80\x01"[below(5)]); break;         // interesting byte
                case 3: s.insert(at, std::string(1 + below(16), char(below(256)))); break;  // inserted run
                case 4: s.erase(at, 1 + below(64)); break;                           // deleted run
                case 5: {                                                           // duplicated run
                    const std::string run = s.substr(at, 1 + below(64));
                    s.insert(std::size_t(below(int(s.size()))), run);
                    break;
                }
            }
        }
        return s;
    }

    std::string json(const nlohmann::json& doc) {
        if (below(4) == 0) return bytes(doc.dump(1));  // text-level damage
        nlohmann::json j = doc;
        const int rounds = 1 + below(3);
        for (int r = 0; r < rounds; ++r) mutate_node(pick(j));
        return j.dump(1);
    }

private:
    /// A random node of j (the root included), by a random walk down.
    nlohmann::json& pick(nlohmann::json& j) {
        nlohmann::json* node = &j;
        while ((node->is_object() || node->is_array()) && !node->empty() && below(3) != 0) {
            auto it = node->begin();
            std::advance(it, below(int(node->size())));
            node = &*it;
        }
        return *node;
    }

    void mutate_node(nlohmann::json& node) {
        static const double huge[] = {1e308, -1e308, 1e300, -1e-320, 4294967297.0, -1.0, 0.0, 1e9, 2147483648.0};
        switch (below(8)) {
            case 0: node = "a string"; break;
            case 1: node = nlohmann::json::array({1, 2, 3}); break;
            case 2: node = nullptr; break;
            case 3: node = nlohmann::json::object({{"unexpected", true}}); break;
            case 4: node = huge[below(9)]; break;
            case 5: node = below(2) == 0; break;
            case 6:
                if (node.is_object() && !node.empty()) {  // a key removed
                    auto it = node.begin();
                    std::advance(it, below(int(node.size())));
                    node.erase(it);
                }
                break;
            case 7: {  // deep nesting
                nlohmann::json deep = 1;
                for (int d = 0; d < 2000; ++d) deep = nlohmann::json::array({std::move(deep)});
                node = std::move(deep);
                break;
            }
        }
    }

    std::mt19937_64 rng_;
};

}  // namespace pnet::test
