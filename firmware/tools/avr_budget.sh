#!/bin/sh
# Print the flash and static RAM use of an AVR ELF and fail when either exceeds its budget.
# usage: avr_budget.sh ELF FLASH_BUDGET_BYTES RAM_BUDGET_BYTES
# Flash = .text + .data (the initial values of .data are stored in flash); RAM = .data + .bss.
set -eu
elf=$1 flash_budget=$2 ram_budget=$3
# Berkeley format: text data bss dec hex filename
set -- $(avr-size --format=berkeley "$elf" | tail -n 1)
text=$1 data=$2 bss=$3
flash=$((text + data))
ram=$((data + bss))
echo "flash: $flash bytes of $flash_budget budget (.text $text + .data $data; chip 32768 - 2048 bootloader = 30720, $((30720 - flash)) free)"
echo "static RAM: $ram bytes of $ram_budget budget (.data $data + .bss $bss; chip 2048, rest is stack)"
status=0
if [ "$flash" -gt "$flash_budget" ]; then echo "FAIL: flash over budget by $((flash - flash_budget)) bytes"; status=1; fi
if [ "$ram" -gt "$ram_budget" ]; then echo "FAIL: static RAM over budget by $((ram - ram_budget)) bytes"; status=1; fi
exit $status
