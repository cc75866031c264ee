// Checkpoint state (state_archive.hpp, Stepper::save_state/load_state): a stepper restored into a
// fresh one continues bit for bit; a state that does not fit is refused with the block's name.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

#include "random_system.hpp"
#include "stable_step.hpp"
#include "state_archive.hpp"
#include "stepper.hpp"

using namespace cavern;
using namespace cavern::testing;

TEST(StateArchive, RoundTripsBlocksAndRefusesOtherSizesAndMissingBlocks) {
  StateArchive archive;
  archive.put("x", std::vector<double>{1.5, -2.0, 3.25});
  archive.put_value<std::int8_t>("flag", 3);
  std::vector<double> x(3);
  archive.get("x", x);
  EXPECT_EQ(x, (std::vector<double>{1.5, -2.0, 3.25}));
  std::int8_t flag = 0;
  archive.get_value("flag", flag);
  EXPECT_EQ(flag, 3);
  std::vector<double> wrong(4);
  EXPECT_THROW(archive.get("x", wrong), std::invalid_argument);
  EXPECT_THROW(archive.get("y", x), std::invalid_argument);
}

namespace {
struct MotionState {
  std::vector<double> u, v, a;
};
}  // namespace

TEST(StateArchive, RestoredStepperContinuesBitForBit) {
  const BlockSystem system = random_spd_system(40, 3, 7);
  const double dt = 0.5 * 2.0 / std::sqrt(gershgorin_bound(system.view(), system.mass.data()));
  const StepperParameters parameters{dt, 0.3, 0.001};
  std::mt19937_64 generator(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  MotionState start{std::vector<double>(system.n_dofs()), std::vector<double>(system.n_dofs()),
            std::vector<double>(system.n_dofs(), 0.0)};
  for (double& value : start.u) value = 0.01 * uniform(generator);
  for (double& value : start.v) value = 0.1 * uniform(generator);

  // Uninterrupted: 60 steps, then 60 more.
  Stepper reference(system.view(), system.mass.data(), parameters);
  MotionState whole = start;
  double t = reference.run(whole.u.data(), whole.v.data(), whole.a.data(), 60, 0.0);
  StateArchive archive;
  reference.save_state(archive);
  const MotionState at_checkpoint = whole;
  reference.run(whole.u.data(), whole.v.data(), whole.a.data(), 60, t);

  // A new stepper from the checkpoint.
  Stepper restored(system.view(), system.mass.data(), parameters);
  restored.load_state(archive);
  MotionState resumed = at_checkpoint;
  restored.run(resumed.u.data(), resumed.v.data(), resumed.a.data(), 60, t);
  EXPECT_EQ(resumed.u, whole.u);
  EXPECT_EQ(resumed.v, whole.v);
  EXPECT_EQ(resumed.a, whole.a);
  const EnergyReport expected = reference.energy(), got = restored.energy();
  EXPECT_GT(expected.damping_work, 0.0);  // the account ran, and is carried over
  EXPECT_EQ(got.total, expected.total);
  EXPECT_EQ(got.initial, expected.initial);
  EXPECT_EQ(got.damping_work, expected.damping_work);
  EXPECT_EQ(got.balance, expected.balance);

  // A stepper of another time step or size refuses the state.
  Stepper other_dt(system.view(), system.mass.data(), {0.5 * dt, 0.3, 0.001});
  EXPECT_THROW(other_dt.load_state(archive), std::invalid_argument);
  const BlockSystem smaller = random_spd_system(39, 3, 7);
  Stepper other_size(smaller.view(), smaller.mass.data(), parameters);
  EXPECT_THROW(other_size.load_state(archive), std::invalid_argument);
}
