// Which instruction sets the CPU running this process has, detected once: the SFF kernels are
// compiled for AVX2 and AVX-512 beside the portable code and only called where these say yes.
#pragma once

namespace inspection {

bool CpuHasAvx2();
bool CpuHasAvx512();  // AVX-512F, and AVX2 (the AVX-512 kernels are used with the AVX2 ones)

}  // namespace inspection
