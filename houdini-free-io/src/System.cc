#include <turbio/System.h>

#include <fstream>

#include <sys/resource.h>
#include <thread>

namespace turbio {

long long peakRssBytes()
{
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("VmHWM:", 0) == 0) return std::stoll(line.substr(6)) * 1024;
    return -1;
}

double cpuSeconds()
{
    rusage u{};
    if (getrusage(RUSAGE_SELF, &u) != 0) return -1.0;
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

std::string machineDescription()
{
    std::ifstream in("/proc/cpuinfo");
    std::string line, model = "unknown CPU";
    while (std::getline(in, line))
        if (line.rfind("model name", 0) == 0) {
            const size_t colon = line.find(':');
            if (colon != std::string::npos) model = line.substr(colon + 2);
            break;
        }
    return model + " (" + std::to_string(std::thread::hardware_concurrency()) + " threads)";
}

} // namespace turbio
