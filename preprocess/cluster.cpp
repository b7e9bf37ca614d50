#include "preprocess/cluster.h"

// The C API only: mpi.h would otherwise pull in the deprecated C++ bindings (libmpi_cxx).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#include <sched.h>

#include <algorithm>
#include <cstdlib>
#include <memory>
#include <thread>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include "common/serial.h"

namespace sa {
namespace {

bool gStarted = false;
int gRank = 0, gSize = 1;
std::unique_ptr<tbb::global_control> gThreads;

bool envSet(const char* name) {
  const char* v = std::getenv(name);
  return v && *v;
}

// mpirun (OpenMPI), or srun with the PMIx or PMI-2 plugin.
bool launchedByMpi() {
  return envSet("OMPI_COMM_WORLD_SIZE") || envSet("PMIX_RANK") || envSet("PMI_RANK") || envSet("PMI_SIZE");
}

int cpusAllowed() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return std::max(1u, std::thread::hardware_concurrency());
  return std::max(1, CPU_COUNT(&set));
}

// Ranks sharing this node.
int localRanks() {
  MPI_Comm local;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &local);
  int n = 1;
  MPI_Comm_size(local, &n);
  MPI_Comm_free(&local);
  return n;
}

// MPI counts are int: large buffers go in pieces.
constexpr uint64_t kPiece = uint64_t(1) << 30;

void bcastBytes(uint8_t* data, uint64_t n, int root) {
  for (uint64_t at = 0; at < n; at += kPiece)
    MPI_Bcast(data + at, static_cast<int>(std::min(kPiece, n - at)), MPI_BYTE, root, MPI_COMM_WORLD);
}

}  // namespace

Status Cluster::start() {
  if (gStarted) return Status::ok();
  if (!launchedByMpi()) {
    const char* tasks = std::getenv("SLURM_NTASKS");
    if (envSet("SLURM_PROCID") && tasks && std::atoi(tasks) > 1)
      return Status::badInput(
          "started by srun as one of " + std::string(tasks) +
          " tasks without an MPI plugin: each would pack the whole input alone; use srun --mpi=pmix (or mpirun)");
    return Status::ok();
  }
  int provided = 0;
  if (MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
    return Status::internal("MPI_Init failed");
  gStarted = true;
  MPI_Comm_rank(MPI_COMM_WORLD, &gRank);
  MPI_Comm_size(MPI_COMM_WORLD, &gSize);
  // A rank bound to fewer cores than the machine has (mpirun binds small jobs to cores) uses
  // those; an unbound one its share of the node.
  int cores = cpusAllowed();
  if (cores >= int(std::thread::hardware_concurrency())) cores = std::max(1, cores / localRanks());
  gThreads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, size_t(cores));
  return Status::ok();
}

void Cluster::stop() {
  if (!gStarted) return;
  gThreads.reset();
  MPI_Finalize();
  gStarted = false;
}

int Cluster::rank() { return gRank; }
int Cluster::size() { return gSize; }

int Cluster::threads() {
  return static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

void Cluster::broadcast(std::vector<uint8_t>& bytes, int root) {
  if (!gStarted || gSize == 1) return;
  uint64_t n = bytes.size();
  MPI_Bcast(&n, 1, MPI_UINT64_T, root, MPI_COMM_WORLD);
  bytes.resize(n);
  bcastBytes(bytes.data(), n, root);
}

std::vector<std::vector<uint8_t>> Cluster::allGather(const std::vector<uint8_t>& mine) {
  std::vector<std::vector<uint8_t>> all(gSize);
  if (!gStarted || gSize == 1) {
    all[0] = mine;
    return all;
  }
  const uint64_t n = mine.size();
  std::vector<uint64_t> sizes(gSize);
  MPI_Allgather(&n, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD);
  for (int r = 0; r < gSize; ++r) {
    all[r] = r == gRank ? mine : std::vector<uint8_t>(sizes[r]);
    bcastBytes(all[r].data(), sizes[r], r);
  }
  return all;
}

Status Cluster::agree(const Status& mine) {
  if (!gStarted || gSize == 1) return mine;
  ByteWriter w;
  w.put<int>(static_cast<int>(mine.kind()));
  w.put(mine.message());
  for (const std::vector<uint8_t>& b : allGather(w.bytes())) {
    ByteReader r(b);
    int kind = 0;
    std::string msg;
    r.get(kind);
    r.get(msg);
    if (kind == static_cast<int>(ErrorKind::kBadInput)) return Status::badInput(msg);
    if (kind != static_cast<int>(ErrorKind::kNone)) return Status::internal(msg);
  }
  return Status::ok();
}

}  // namespace sa
