// Stand-in for google/marl's scheduler.h (its repository is not reachable from this machine):
// a scheduled task runs at once on the calling thread. Only Polylidar3D's mesh paths schedule
// tasks; the point-cloud path it is timed on never does.
#pragma once
#include <functional>
#include <memory>
#include <mutex>
namespace marl {
class Scheduler {
  public:
    class Config {
      public:
        Config& setWorkerThreadCount(int n) {
            threads = n;
            return *this;
        }
        int threads = 0;
    };
    explicit Scheduler(const Config&) {}
    void bind() {}
    void unbind() {}
};
template <typename F> void schedule(F&& f) { f(); }
} // namespace marl
