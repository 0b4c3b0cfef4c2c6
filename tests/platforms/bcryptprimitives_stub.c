/* Test-only stand-in for Windows 10's bcryptprimitives.dll, which Wine 8 lacks: Rust's
 * standard library asks it for ProcessPrng (random bytes, e.g. for HashMap seeds). Built with
 * mingw-w64 by tests/platforms/test_windows.py and put beside the embeddable python.exe of the
 * Wine test only; it never goes into a zip. RtlGenRandom is advapi32's SystemFunction036. */
#include <windows.h>

BOOLEAN WINAPI SystemFunction036(PVOID buffer, ULONG length);

__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T length)
{
    while (length > 0) {
        ULONG chunk = length > 0x10000000 ? 0x10000000 : (ULONG)length;
        if (!SystemFunction036(data, chunk))
            return FALSE;
        data += chunk;
        length -= chunk;
    }
    return TRUE;
}
