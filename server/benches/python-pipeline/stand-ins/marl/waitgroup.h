// Stand-in for google/marl's waitgroup.h: with every task run at once (scheduler.h), there is
// nothing left to wait for.
#pragma once
#include <memory>
namespace marl {
class WaitGroup {
  public:
    explicit WaitGroup(int n = 0) : count_(std::make_shared<int>(n)) {}
    void add(int n = 1) const { *count_ += n; }
    bool done() const { return --*count_ == 0; }
    void wait() const {}
  private:
    std::shared_ptr<int> count_;
};
} // namespace marl
