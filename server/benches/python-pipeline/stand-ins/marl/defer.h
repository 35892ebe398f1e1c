// Stand-in for google/marl's defer.h (its repository is not reachable from this machine):
// `defer(statement)` runs the statement when the enclosing scope ends.
#pragma once
#include <utility>
namespace marl {
template <typename F> class Finally {
  public:
    explicit Finally(F f) : f_(std::move(f)) {}
    Finally(Finally&& other) : f_(std::move(other.f_)), armed_(other.armed_) { other.armed_ = false; }
    ~Finally() {
        if (armed_) f_();
    }
    Finally(const Finally&) = delete;
    Finally& operator=(const Finally&) = delete;
  private:
    F f_;
    bool armed_ = true;
};
template <typename F> Finally<F> make_finally(F f) { return Finally<F>(std::move(f)); }
} // namespace marl
#define MARL_CONCAT_(a, b) a##b
#define MARL_CONCAT(a, b) MARL_CONCAT_(a, b)
#define defer(x) auto MARL_CONCAT(marl_defer_, __LINE__) = marl::make_finally([&] { x; })
