#pragma once
// Typed test suites run in 2D and in 3D: TypeParam::value is the dimension.
#include <gtest/gtest.h>

#include <type_traits>

namespace pnet::test {

using Dims = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;

}  // namespace pnet::test

/// Declares the typed test suite `Suite` over test::Dims (tests Suite/0.* in 2D, Suite/1.* in 3D).
#define PNET_TYPED_TEST_SUITE_2D_3D(Suite)    \
    template <typename T>                     \
    class Suite : public ::testing::Test {};  \
    TYPED_TEST_SUITE(Suite, ::pnet::test::Dims)
