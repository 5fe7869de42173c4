//! The Modbus transactions of one loop cycle, derived from a register map.
//!
//! A cycle writes the set-point and reads the position (and the status register when the map has
//! one): either one Read/Write Multiple Registers transaction (FC 23) or a Write Multiple
//! Registers (FC 16; Write Single Register, FC 6, with `fc6`) followed by a read (FC 3 or FC 4). The position and a status register in the
//! same table within [`MAX_JOINED_SPAN`] registers are read together. The plan also knows the RTU
//! frame sizes of each transaction, which the bus budget uses. Nothing here does I/O.

use super::map::{RegisterMap, Table};

/// Position and status closer than this many registers are read in one request.
pub const MAX_JOINED_SPAN: u16 = 16;

/// One request/response exchange.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transaction {
    /// FC 16: write `count` holding registers from `address`.
    Write { address: u16, count: u16 },
    /// FC 6: write the one holding register at `address`.
    WriteSingle { address: u16 },
    /// FC 3 (holding) or FC 4 (input): read `count` registers from `address`.
    Read {
        table: Table,
        address: u16,
        count: u16,
    },
    /// FC 23: write `write_count` registers at `write_address`, then read `read_count` at
    /// `read_address` (both holding).
    ReadWrite {
        read_address: u16,
        read_count: u16,
        write_address: u16,
        write_count: u16,
    },
}

impl Transaction {
    /// The Modbus function code.
    pub fn function_code(&self) -> u8 {
        match self {
            Transaction::Write { .. } => 16,
            Transaction::WriteSingle { .. } => 6,
            Transaction::Read {
                table: Table::Holding,
                ..
            } => 3,
            Transaction::Read {
                table: Table::Input,
                ..
            } => 4,
            Transaction::ReadWrite { .. } => 23,
        }
    }

    /// RTU request frame size in bytes (address, PDU, CRC).
    pub fn rtu_request_bytes(&self) -> usize {
        match *self {
            // addr, fc, start(2), qty(2), crc(2); FC 6: addr, fc, address(2), value(2), crc(2)
            Transaction::Read { .. } | Transaction::WriteSingle { .. } => 8,
            // addr, fc, start(2), qty(2), byte count, data, crc(2)
            Transaction::Write { count, .. } => 9 + 2 * usize::from(count),
            // addr, fc, read start(2), read qty(2), write start(2), write qty(2), byte count, data, crc(2)
            Transaction::ReadWrite { write_count, .. } => 13 + 2 * usize::from(write_count),
        }
    }

    /// RTU response frame size in bytes for a normal (non-exception) reply.
    pub fn rtu_response_bytes(&self) -> usize {
        match *self {
            // addr, fc, byte count, data, crc(2)
            Transaction::Read { count, .. } => 5 + 2 * usize::from(count),
            // addr, fc, start(2), qty(2), crc(2); FC 6 echoes its request
            Transaction::Write { .. } | Transaction::WriteSingle { .. } => 8,
            Transaction::ReadWrite { read_count, .. } => 5 + 2 * usize::from(read_count),
        }
    }
}

/// Where a value sits in the words returned by the plan's transactions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot {
    /// Index of the transaction whose reply holds the value.
    pub transaction: usize,
    /// Offset of the value's first word in that reply.
    pub offset: usize,
}

/// The transactions of one cycle and where position and status are found in their replies.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    /// In the order they are sent.
    pub transactions: Vec<Transaction>,
    /// Where the position words are.
    pub position: Slot,
    /// Where the status word is, if the map has one.
    pub status: Option<Slot>,
}

impl Plan {
    /// The plan for a (validated) map on Modbus TCP, whose transaction ids tell a late reply
    /// from the current one: the read block is the position and, when near, the status.
    pub fn new(map: &RegisterMap) -> Plan {
        Plan::build(map, false)
    }

    /// The plan on Modbus RTU, whose frames carry no transaction id: the read block also takes
    /// in the set-point register when it is near (same table, within [`MAX_JOINED_SPAN`]), so
    /// every reply reads back the set-point just written and a late reply to an earlier cycle
    /// can be told by its older set-point ([`super::wire::RtuWire`]).
    pub fn rtu(map: &RegisterMap) -> Plan {
        Plan::build(map, true)
    }

    fn build(map: &RegisterMap, readback: bool) -> Plan {
        let pos = map.position;
        // The read block: the position, with the status and (RTU) the set-point when they sit
        // in its table close enough to be read in one request.
        let mut block = (pos.address, pos.format.width());
        let mut joined_status = None;
        if let Some(s) = map.status.filter(|s| s.table == pos.table) {
            if let Some(b) = widened(block, (s.address, 1)) {
                block = b;
                joined_status = Some(s.address);
            }
        }
        let sp = map.setpoint;
        if readback && sp.table == pos.table {
            block = widened(block, (sp.address, sp.format.width())).unwrap_or(block);
        }
        let (read_start, read_count) = block;
        let joined = joined_status.map(|a| a - read_start);
        let first_read = if map.fc23 {
            Transaction::ReadWrite {
                read_address: read_start,
                read_count,
                write_address: map.setpoint.address,
                write_count: map.setpoint.format.width(),
            }
        } else {
            Transaction::Read {
                table: pos.table,
                address: read_start,
                count: read_count,
            }
        };
        let mut transactions = Vec::with_capacity(3);
        if map.fc6 {
            transactions.push(Transaction::WriteSingle {
                address: map.setpoint.address,
            });
        } else if !map.fc23 {
            transactions.push(Transaction::Write {
                address: map.setpoint.address,
                count: map.setpoint.format.width(),
            });
        }
        let read_index = transactions.len();
        transactions.push(first_read);
        let position = Slot {
            transaction: read_index,
            offset: usize::from(pos.address - read_start),
        };
        let status = match (map.status, joined) {
            (None, _) => None,
            (Some(_), Some(off)) => Some(Slot {
                transaction: read_index,
                offset: usize::from(off),
            }),
            (Some(s), None) => {
                transactions.push(Transaction::Read {
                    table: s.table,
                    address: s.address,
                    count: 1,
                });
                Some(Slot {
                    transaction: transactions.len() - 1,
                    offset: 0,
                })
            }
        };
        Plan {
            transactions,
            position,
            status,
        }
    }
}

impl Plan {
    /// True when a read of the plan holds the set-point register of `map` (its reply reads the
    /// set-point back).
    pub fn reads_back(&self, map: &RegisterMap) -> bool {
        let sp = map.setpoint;
        let within = |start: u16, count: u16| {
            sp.address >= start
                && u32::from(sp.address) + u32::from(sp.format.width())
                    <= u32::from(start) + u32::from(count)
        };
        self.transactions.iter().any(|t| match *t {
            Transaction::Read {
                table: Table::Holding,
                address,
                count,
            } => within(address, count),
            Transaction::ReadWrite {
                read_address,
                read_count,
                ..
            } => within(read_address, read_count),
            _ => false,
        })
    }
}

/// The block `(start, count)` widened to take in `part`, if it then spans at most
/// [`MAX_JOINED_SPAN`] registers.
fn widened(block: (u16, u16), part: (u16, u16)) -> Option<(u16, u16)> {
    let end = |(start, count): (u16, u16)| u32::from(start) + u32::from(count);
    let start = block.0.min(part.0);
    let span = end(block).max(end(part)) - u32::from(start);
    (span <= u32::from(MAX_JOINED_SPAN)).then_some((start, span as u16))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Format, Register, StatusRegister};

    #[test]
    fn default_map_writes_then_reads() {
        let p = Plan::new(&RegisterMap::default());
        assert_eq!(
            p.transactions,
            vec![
                Transaction::Write {
                    address: 0,
                    count: 1
                },
                Transaction::Read {
                    table: Table::Holding,
                    address: 1,
                    count: 1
                }
            ]
        );
        assert_eq!(
            p.position,
            Slot {
                transaction: 1,
                offset: 0
            }
        );
        assert_eq!(p.transactions[0].rtu_request_bytes(), 11);
        assert_eq!(p.transactions[0].rtu_response_bytes(), 8);
        assert_eq!(p.transactions[1].rtu_request_bytes(), 8);
        assert_eq!(p.transactions[1].rtu_response_bytes(), 7);
    }

    #[test]
    fn fc6_writes_one_register() {
        let map = RegisterMap {
            fc6: true,
            ..RegisterMap::default()
        };
        let p = Plan::new(&map);
        assert_eq!(p.transactions[0], Transaction::WriteSingle { address: 0 });
        assert_eq!(p.transactions[0].function_code(), 6);
        assert_eq!(p.transactions[0].rtu_request_bytes(), 8);
        assert_eq!(p.transactions[0].rtu_response_bytes(), 8);
        assert_eq!(p.position.transaction, 1);
    }

    #[test]
    fn fc23_with_joined_status() {
        let map = RegisterMap {
            fc23: true,
            status: Some(StatusRegister {
                table: Table::Holding,
                address: 3,
                setpoint_error_bit: 0,
            }),
            ..RegisterMap::default()
        };
        let p = Plan::new(&map);
        assert_eq!(
            p.transactions,
            vec![Transaction::ReadWrite {
                read_address: 1,
                read_count: 3,
                write_address: 0,
                write_count: 1
            }]
        );
        assert_eq!(
            p.status,
            Some(Slot {
                transaction: 0,
                offset: 2
            })
        );
        assert_eq!(p.transactions[0].function_code(), 23);
        assert_eq!(p.transactions[0].rtu_request_bytes(), 15);
        assert_eq!(p.transactions[0].rtu_response_bytes(), 11);
    }

    #[test]
    fn rtu_reads_the_set_point_back_when_it_is_near() {
        let map = RegisterMap {
            fc23: true,
            status: Some(StatusRegister {
                table: Table::Holding,
                address: 2,
                setpoint_error_bit: 0,
            }),
            ..RegisterMap::default()
        };
        let p = Plan::rtu(&map);
        assert_eq!(
            p.transactions,
            vec![Transaction::ReadWrite {
                read_address: 0,
                read_count: 3,
                write_address: 0,
                write_count: 1
            }]
        );
        assert_eq!(
            (p.position.offset, p.status.map(|s| s.offset)),
            (1, Some(2))
        );
        assert!(p.reads_back(&map) && !Plan::new(&map).reads_back(&map));
        // FC 16 then FC 3 over set-point and position.
        let p = Plan::rtu(&RegisterMap::default());
        assert_eq!(
            p.transactions[1],
            Transaction::Read {
                table: Table::Holding,
                address: 0,
                count: 2
            }
        );
        assert_eq!(p.position.offset, 1);
        // A position in the input table, or far away, cannot read it back.
        let far = RegisterMap {
            position: Register {
                address: 40,
                ..RegisterMap::default().position
            },
            ..RegisterMap::default()
        };
        assert!(!Plan::rtu(&far).reads_back(&far));
        assert_eq!(Plan::rtu(&far), Plan::new(&far));
    }

    #[test]
    fn far_or_other_table_status_is_read_alone() {
        let map = RegisterMap {
            position: Register {
                table: Table::Input,
                address: 100,
                format: Format::F32,
                scale: 1.0,
                offset: 0.0,
            },
            status: Some(StatusRegister {
                table: Table::Holding,
                address: 101,
                setpoint_error_bit: 0,
            }),
            ..RegisterMap::default()
        };
        let p = Plan::new(&map);
        assert_eq!(p.transactions.len(), 3);
        assert_eq!(
            p.transactions[1],
            Transaction::Read {
                table: Table::Input,
                address: 100,
                count: 2
            }
        );
        assert_eq!(p.transactions[1].function_code(), 4);
        assert_eq!(
            p.status,
            Some(Slot {
                transaction: 2,
                offset: 0
            })
        );
        // Status below the position in the same table: the block starts at the status.
        let map = RegisterMap {
            status: Some(StatusRegister {
                table: Table::Holding,
                address: 1,
                setpoint_error_bit: 0,
            }),
            position: Register {
                address: 5,
                ..RegisterMap::default().position
            },
            ..RegisterMap::default()
        };
        let p = Plan::new(&map);
        assert_eq!(
            p.transactions[1],
            Transaction::Read {
                table: Table::Holding,
                address: 1,
                count: 5
            }
        );
        assert_eq!(
            p.position,
            Slot {
                transaction: 1,
                offset: 4
            }
        );
        assert_eq!(
            p.status,
            Some(Slot {
                transaction: 1,
                offset: 0
            })
        );
    }
}
