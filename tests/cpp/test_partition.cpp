// A model split into two ranks' shares (Stepper::set_partition, docs/scaling.md) and stepped in
// two threads that exchange the ghosts' v and a through memory, as MPI ranks do through
// messages: every owned node follows the whole model's stepper, and the shares' energy accounts
// add up to the whole's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <thread>
#include <vector>

#include "random_system.hpp"
#include "shares.hpp"
#include "stable_step.hpp"
#include "stepper.hpp"

namespace cavern {
namespace {

using testing::Barrier;
using testing::make_share;
using testing::Share;

/// The two shares' ghost exchange through memory: each posts v, a of every node, the other reads
/// its ghosts' values by global number.
class MemoryExchange : public NodeExchange {
 public:
  MemoryExchange(const Share& mine, std::vector<double>& mailbox_out,
                 const std::vector<double>& mailbox_in, Barrier& barrier)
      : mine_(mine), out_(mailbox_out), in_(mailbox_in), barrier_(barrier) {}

  void exchange(double* v, double* a) override {
    for (std::int64_t l = 0; l < mine_.n_owned; ++l)
      for (int c = 0; c < 3; ++c) {
        out_[6 * mine_.nodes[l] + c] = v[3 * l + c];
        out_[6 * mine_.nodes[l] + 3 + c] = a[3 * l + c];
      }
    barrier_.arrive_and_wait();  // both posted
    for (std::size_t l = mine_.n_owned; l < mine_.nodes.size(); ++l)
      for (int c = 0; c < 3; ++c) {
        v[3 * l + c] = in_[6 * mine_.nodes[l] + c];
        a[3 * l + c] = in_[6 * mine_.nodes[l] + 3 + c];
      }
    barrier_.arrive_and_wait();  // both read: the mailboxes may be written again
  }

 private:
  const Share& mine_;
  std::vector<double>& out_;
  const std::vector<double>& in_;
  Barrier& barrier_;
};

TEST(Partition, TwoSharesSteppedLikeRanksFollowTheWholeModel) {
  const testing::BlockSystem whole = testing::random_spd_system(60, 3, 11);
  const double dt = 0.8 * 2.0 / std::sqrt(gershgorin_bound(whole.view(), whole.mass.data()));
  const StepperParameters parameters{dt, 0.05, 0.0};
  const std::vector<std::int32_t> dashpot_nodes = {3, 41};  // one in each share
  std::vector<double> C(18, 0.0);
  for (int k = 0; k < 2; ++k)
    for (int c = 0; c < 3; ++c) C[9 * k + 4 * c] = 0.7;

  std::mt19937_64 generator(5);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const std::int64_t n_dofs = whole.n_dofs();
  std::vector<double> u0(n_dofs), v0(n_dofs), a0(n_dofs, 0.0);
  for (double& value : u0) value = 0.01 * uniform(generator);
  for (double& value : v0) value = 0.1 * uniform(generator);
  constexpr std::int64_t kSteps = 400;

  Stepper reference(whole.view(), whole.mass.data(), parameters);
  reference.set_dashpots(dashpot_nodes.data(), 2, C.data());
  std::vector<double> u = u0, v = v0, a = a0;
  reference.reset_energy(u.data(), v.data(), a.data(), 0.0);
  reference.run(u.data(), v.data(), a.data(), kSteps, 0.0);

  const Share shares[2] = {make_share(whole, 0, 30), make_share(whole, 30, 60)};
  ASSERT_GT(shares[0].nodes.size(), 30u);  // there are ghosts to exchange
  std::vector<double> mailbox[2] = {std::vector<double>(2 * n_dofs), std::vector<double>(2 * n_dofs)};
  Barrier barrier;
  std::vector<double> lu[2], lv[2], la[2];
  EnergyReport reports[2];
  auto rank = [&](int r) {
    const Share& share = shares[r];
    Stepper stepper(share.system.view(), share.system.mass.data(), parameters);
    const std::int32_t local_dashpot[1] = {r == 0 ? 3 : 41 - 30};
    stepper.set_dashpots(local_dashpot, 1, C.data() + 9 * r);
    stepper.set_partition(share.n_owned,
                          std::make_shared<MemoryExchange>(share, mailbox[r], mailbox[1 - r], barrier));
    for (const std::int64_t node : share.nodes)
      for (int c = 0; c < 3; ++c) {
        lu[r].push_back(u0[3 * node + c]);
        lv[r].push_back(v0[3 * node + c]);
        la[r].push_back(a0[3 * node + c]);
      }
    stepper.reset_energy(lu[r].data(), lv[r].data(), la[r].data(), 0.0);
    stepper.run(lu[r].data(), lv[r].data(), la[r].data(), kSteps, 0.0);
    reports[r] = stepper.energy();
  };
  std::thread first(rank, 0), second(rank, 1);
  first.join();
  second.join();

  double largest = 0.0, difference = 0.0;
  for (int r = 0; r < 2; ++r)
    for (std::int64_t l = 0; l < static_cast<std::int64_t>(shares[r].nodes.size()); ++l)
      for (int c = 0; c < 3; ++c) {  // owned and ghosts: a ghost holds its owner's state
        const std::int64_t d = 3 * shares[r].nodes[l] + c;
        largest = std::max(largest, std::abs(u[d]));
        difference = std::max(difference, std::abs(lu[r][3 * l + c] - u[d]));
      }
  EXPECT_GT(largest, 1e-3);  // the model moved
  EXPECT_LT(difference, 1e-13 * largest);

  const EnergyReport whole_report = reference.energy();
  const double scale = std::max(std::abs(whole_report.total), whole_report.damping_work);
  EXPECT_GT(whole_report.damping_work, 1e-3 * scale);  // the dashpots and alpha did work
  EXPECT_NEAR(reports[0].kinetic + reports[1].kinetic, whole_report.kinetic, 1e-12 * scale);
  EXPECT_NEAR(reports[0].strain + reports[1].strain, whole_report.strain, 1e-12 * scale);
  EXPECT_NEAR(reports[0].initial + reports[1].initial, whole_report.initial, 1e-12 * scale);
  EXPECT_NEAR(reports[0].damping_work + reports[1].damping_work, whole_report.damping_work,
              1e-12 * scale);
  EXPECT_LT(std::abs(reports[0].balance + reports[1].balance), 1e-12 * scale);
}

TEST(Partition, EffectsOnGhostNodesAreRefused) {
  // A share's dashpots (and constraints, providers, pairs) must be on its owned nodes: its ghosts'
  // rows are its owner's to load. Stepping one on a ghost is refused with the node named.
  const testing::BlockSystem whole = testing::random_spd_system(60, 3, 11);
  const Share share = make_share(whole, 0, 30);
  ASSERT_GT(share.nodes.size(), 30u);
  const double dt = 0.5 * 2.0 / std::sqrt(gershgorin_bound(whole.view(), whole.mass.data()));
  const std::int64_t n_dofs = 3 * static_cast<std::int64_t>(share.nodes.size());
  std::vector<double> u(n_dofs, 0.0), v(n_dofs, 0.0), a(n_dofs, 0.0);
  const std::vector<double> C = {0.7, 0, 0, 0, 0.7, 0, 0, 0, 0.7};
  Stepper stepper(share.system.view(), share.system.mass.data(), StepperParameters{dt, 0.0, 0.0});
  const std::int32_t ghost[1] = {static_cast<std::int32_t>(share.n_owned)};
  stepper.set_dashpots(ghost, 1, C.data());
  stepper.set_partition(share.n_owned, nullptr);
  try {
    stepper.run(u.data(), v.data(), a.data(), 1, 0.0);
    ADD_FAILURE() << "a dashpot on a ghost node was stepped";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("a dashpot at node 30"), std::string::npos)
        << error.what();
  }
  // On an owned node the same share steps.
  const std::int32_t owned[1] = {3};
  stepper.set_dashpots(owned, 1, C.data());
  EXPECT_NO_THROW(stepper.run(u.data(), v.data(), a.data(), 1, 0.0));
}

}  // namespace
}  // namespace cavern
