// Exits 0 when the CPU running it has the x86-64-v3 instruction set (AVX2, FMA, BMI2, ...):
// CMakeLists.txt then builds the kernels for that level.
int main() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("x86-64-v3") ? 0 : 1;
}
