mod alarms;
mod cases;
mod guard;
mod oracle;
mod programmes;
mod rules;
