//! The tag database as an OPC UA address space: one folder per name part
//! under a `Tags` folder in the Objects folder, one variable per tag. Values
//! are read from the tag database when asked (never from a copy), monitored
//! items are fed from its change subscription, and writes go through the
//! same confirmed, audited command path as an HMI write.

use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::Arc;

use async_trait::async_trait;
use gridscada_tagdb::WriteError;
use gridscada_tagdb::{TagDb, TagId, Update};
use gridscada_web::command::{write_tag, WriteRefused};
use gridscada_web::WebState;
use opcua::server::address_space::{AccessLevel, AddressSpace, ObjectBuilder, VariableBuilder};
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{
    InMemoryNodeManagerImpl, InMemoryNodeManagerImplBuilder,
};
use opcua::server::node_manager::{ParsedReadValueId, RequestContext, ServerContext, WriteNode};
use opcua::server::{CreateMonitoredItem, SubscriptionCache};
use opcua::sync::RwLock;
use opcua::types::{
    AttributeId, DataTypeId, DataValue, DateTime, EUInformation, LocalizedText, NodeId,
    NumericRange, ObjectId, StatusCode, TimestampsToReturn, VariableTypeId,
};

use crate::model::{data_type_of, data_value, node_path, value_of};
use crate::users::Users;
use crate::Metrics;

/// The namespace of the tag nodes.
pub const NAMESPACE_URI: &str = "urn:gridscada:tags";

/// Where the tags are: one entry per tag id, plus the way back from a node.
pub(crate) struct TagSpace {
    pub db: Arc<TagDb>,
    pub web: WebState,
    /// Per tag id: its node and OPC UA data type.
    pub nodes: Vec<(NodeId, DataTypeId)>,
    pub by_node: HashMap<NodeId, TagId>,
    pub metrics: Arc<Metrics>,
    pub users: Arc<Users>,
}

impl TagSpace {
    pub fn new(ns: u16, web: WebState, metrics: Arc<Metrics>, users: Arc<Users>) -> TagSpace {
        let db = web.db.clone();
        let mut nodes = Vec::with_capacity(db.len());
        let mut by_node = HashMap::with_capacity(db.len());
        for (id, meta) in db.all_meta() {
            let register = web.plant.tag(&meta.name).map(|t| t.data_type());
            let node = NodeId::new(ns, meta.name.to_string());
            by_node.insert(node.clone(), id);
            nodes.push((node, data_type_of(meta.kind, register)));
        }
        TagSpace {
            db,
            web,
            nodes,
            by_node,
            metrics,
            users,
        }
    }

    fn read(&self, id: TagId, ttr: TimestampsToReturn) -> DataValue {
        let Some(sample) = self.db.get(id) else {
            return DataValue::new_now_status(
                opcua::types::Variant::Empty,
                StatusCode::BadNodeIdUnknown,
            );
        };
        let mut dv = data_value(&sample, self.nodes[id.index()].1, DateTime::now());
        match ttr {
            TimestampsToReturn::Source => dv.server_timestamp = None,
            TimestampsToReturn::Server => dv.source_timestamp = None,
            TimestampsToReturn::Neither => {
                dv.source_timestamp = None;
                dv.server_timestamp = None;
            }
            _ => {}
        }
        dv
    }

    /// Builds the folders and variables in `space` under `root`.
    fn populate(&self, space: &mut AddressSpace, ns: u16, root: &NodeId) {
        let mut folders: HashMap<String, NodeId> = HashMap::new();
        for (id, meta) in self.db.all_meta() {
            let (path, leaf) = node_path(&meta.name);
            let mut parent = root.clone();
            for (full, part) in path {
                parent = match folders.get(full) {
                    Some(n) => n.clone(),
                    None => {
                        // A folder's id is its path with a trailing dot, so it
                        // never equals a tag's (`A.B` as a tag and as a folder).
                        let node = NodeId::new(ns, format!("{full}."));
                        ObjectBuilder::new(&node, part, part)
                            .is_folder()
                            .organized_by(parent.clone())
                            .insert(space);
                        folders.insert(full.to_string(), node.clone());
                        node
                    }
                };
            }
            let (node, ty) = &self.nodes[id.index()];
            let mut level = AccessLevel::CURRENT_READ;
            if meta.writable {
                level |= AccessLevel::CURRENT_WRITE;
            }
            let type_def = if meta.units.is_empty() {
                VariableTypeId::BaseDataVariableType
            } else {
                VariableTypeId::AnalogItemType
            };
            let mut var = VariableBuilder::new(node, leaf, leaf)
                .data_type(*ty)
                .value_rank(-1)
                .access_level(level)
                .user_access_level(level)
                .minimum_sampling_interval(0.0)
                .has_type_definition(type_def)
                .organized_by(parent);
            if !meta.description.is_empty() {
                var = var.description(LocalizedText::new("", &meta.description));
            }
            var.insert(space);
            if !meta.units.is_empty() {
                // EngineeringUnits: the unit as written in the configuration
                // (no UNECE code: -1, as the specification allows).
                let eu = EUInformation {
                    namespace_uri: "http://www.opcfoundation.org/UA/units/un/cefact".into(),
                    unit_id: -1,
                    display_name: LocalizedText::new("", &meta.units),
                    description: LocalizedText::new("", &meta.units),
                };
                let prop = NodeId::new(ns, format!("{}#EngineeringUnits", meta.name));
                VariableBuilder::new(&prop, "EngineeringUnits", "EngineeringUnits")
                    .data_type(DataTypeId::EUInformation)
                    .value_rank(-1)
                    .value(opcua::types::ExtensionObject::from_message(eu))
                    .has_type_definition(VariableTypeId::PropertyType)
                    .property_of(node.clone())
                    .insert(space);
            }
        }
    }
}

/// Feeds monitored items from the tag database's change subscription. It
/// never holds up the poller: a lagging feed gets a snapshot (TagDb).
pub(crate) async fn feed(space: Arc<TagSpace>, subscriptions: Arc<SubscriptionCache>) {
    let mut sub = space.db.subscribe_all();
    while let Some(update) = sub.recv().await {
        let now = DateTime::now();
        let batch = match &update {
            Update::Changes(b) | Update::Snapshot(b) => b,
        };
        let mut notifier = subscriptions.data_notifier();
        for (id, sample) in &batch.changes {
            let Some((node, ty)) = space.nodes.get(id.index()) else {
                continue;
            };
            if let Some(mut items) = notifier.notify_for(node, AttributeId::Value) {
                items.data_value(data_value(sample, *ty, now));
                space.metrics.notifications.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

pub(crate) struct TagNodesBuilder {
    pub web: WebState,
    pub metrics: Arc<Metrics>,
    pub users: Arc<Users>,
    /// Where the built tag space is handed back (for the feed).
    pub built: Arc<std::sync::OnceLock<Arc<TagSpace>>>,
}

impl InMemoryNodeManagerImplBuilder for TagNodesBuilder {
    type Impl = TagNodes;

    fn build(self, context: ServerContext, address_space: &mut AddressSpace) -> TagNodes {
        let ns = context
            .type_tree
            .write()
            .namespaces_mut()
            .add_namespace(NAMESPACE_URI);
        address_space.add_namespace(NAMESPACE_URI, ns);
        let space = Arc::new(TagSpace::new(ns, self.web, self.metrics, self.users));
        let _ = self.built.set(space.clone());
        TagNodes {
            namespace: NamespaceMetadata {
                namespace_uri: NAMESPACE_URI.into(),
                namespace_index: ns,
                ..Default::default()
            },
            space,
        }
    }
}

pub(crate) struct TagNodes {
    namespace: NamespaceMetadata,
    space: Arc<TagSpace>,
}

#[async_trait]
impl InMemoryNodeManagerImpl for TagNodes {
    async fn init(&self, address_space: &mut AddressSpace, _context: ServerContext) {
        let ns = self.namespace.namespace_index;
        let root = NodeId::new(ns, 0u32);
        ObjectBuilder::new(&root, "Tags", "Tags")
            .is_folder()
            .organized_by(ObjectId::ObjectsFolder)
            .insert(address_space);
        self.space.populate(address_space, ns, &root);
    }

    fn name(&self) -> &str {
        "gridscada-tags"
    }

    fn namespaces(&self) -> Vec<NamespaceMetadata> {
        vec![self.namespace.clone()]
    }

    async fn read_values(
        &self,
        context: &RequestContext,
        address_space: &RwLock<AddressSpace>,
        nodes: &[&ParsedReadValueId],
        _max_age: f64,
        ttr: TimestampsToReturn,
    ) -> Vec<DataValue> {
        let space = address_space.read();
        let out: Vec<DataValue> = nodes
            .iter()
            .map(|n| {
                if let Err(e) = space.validate_node_read(context, n) {
                    return DataValue {
                        status: Some(e),
                        ..Default::default()
                    };
                }
                match self.space.by_node.get(&n.node_id) {
                    Some(&id) if n.index_range == NumericRange::None => self.space.read(id, ttr),
                    Some(_) => DataValue {
                        status: Some(StatusCode::BadIndexRangeNoData),
                        ..Default::default()
                    },
                    // A folder's or property's own value.
                    None => opcua::server::address_space::read_node_value(
                        space.find(&n.node_id).expect("validated above"),
                        context,
                        n,
                        0.0,
                        ttr,
                    ),
                }
            })
            .collect();
        self.space
            .metrics
            .reads
            .fetch_add(out.len() as u64, Ordering::Relaxed);
        out
    }

    async fn create_value_monitored_items(
        &self,
        context: &RequestContext,
        address_space: &RwLock<AddressSpace>,
        items: &mut [&mut &mut CreateMonitoredItem],
    ) {
        let to_read: Vec<_> = items.iter().map(|r| r.item_to_monitor()).collect();
        let values = self
            .read_values(
                context,
                address_space,
                &to_read,
                0.0,
                TimestampsToReturn::Both,
            )
            .await;
        for (value, item) in values.into_iter().zip(items.iter_mut()) {
            let status = value.status();
            if status == StatusCode::BadNodeIdUnknown || status == StatusCode::BadUserAccessDenied {
                item.set_status(status);
                continue;
            }
            item.set_initial_value(value);
            item.set_status(StatusCode::Good);
        }
    }

    async fn write(
        &self,
        context: &RequestContext,
        address_space: &RwLock<AddressSpace>,
        nodes_to_write: &mut [&mut WriteNode],
    ) -> Result<(), StatusCode> {
        let who = self.space.users.principal(context.user_token()).await;
        for w in nodes_to_write.iter_mut() {
            let exists = address_space.read().find(&w.value().node_id).is_some();
            let (status, failed) = self.write_one(&who, w.value(), exists).await;
            let counter = if status.is_good() {
                &self.space.metrics.writes
            } else if failed {
                &self.space.metrics.writes_failed
            } else {
                &self.space.metrics.writes_refused
            };
            counter.fetch_add(1, Ordering::Relaxed);
            w.set_status(status);
        }
        Ok(())
    }
}

impl TagNodes {
    /// The status of one write, and whether the device or the link failed it
    /// (rather than the server refusing it before the device).
    async fn write_one(
        &self,
        who: &Result<gridscada_web::auth::Principal, StatusCode>,
        w: &opcua::server::node_manager::ParsedWriteValue,
        exists: bool,
    ) -> (StatusCode, bool) {
        match self.write_status(who, w, exists).await {
            Ok(status) => (status, false),
            Err(failed) => (failed, true),
        }
    }

    /// Ok: Good or a refusal; Err: what the device or the link failed with.
    async fn write_status(
        &self,
        who: &Result<gridscada_web::auth::Principal, StatusCode>,
        w: &opcua::server::node_manager::ParsedWriteValue,
        exists: bool,
    ) -> Result<StatusCode, StatusCode> {
        let Some(&id) = self.space.by_node.get(&w.node_id) else {
            // A folder or a property: nothing there may be written.
            return Ok(if exists {
                StatusCode::BadNotWritable
            } else {
                StatusCode::BadNodeIdUnknown
            });
        };
        if w.attribute_id != AttributeId::Value {
            return Ok(StatusCode::BadNotWritable);
        }
        if w.index_range != NumericRange::None {
            return Ok(StatusCode::BadWriteNotSupported);
        }
        // The device stamps the value and its quality, not the client (a
        // Good status, which many clients send, says nothing).
        if w.value.status.is_some_and(|s| !s.is_good())
            || w.value.source_timestamp.is_some()
            || w.value.server_timestamp.is_some()
        {
            return Ok(StatusCode::BadWriteNotSupported);
        }
        let Some(value) = w.value.value.as_ref().and_then(value_of) else {
            return Ok(StatusCode::BadTypeMismatch);
        };
        let who = match who {
            Ok(p) => p,
            Err(status) => return Ok(*status),
        };
        let Some(meta) = self.space.db.meta(id) else {
            return Ok(StatusCode::BadNodeIdUnknown);
        };
        let name = meta.name.clone();
        let refused = match write_tag(&self.space.web, who, &name, value, "OPC UA").await {
            Ok(_) => StatusCode::Good,
            Err(WriteRefused::UnknownTag(_)) => StatusCode::BadNodeIdUnknown,
            Err(WriteRefused::Forbidden(_)) if self.space.web.write_role(&name).is_none() => {
                StatusCode::BadNotWritable
            }
            Err(WriteRefused::Forbidden(_)) => StatusCode::BadUserAccessDenied,
            Err(WriteRefused::BadValue(_)) => StatusCode::BadTypeMismatch,
            Err(WriteRefused::NoFieldIo | WriteRefused::Unaudited(_)) => {
                StatusCode::BadResourceUnavailable
            }
            Err(WriteRefused::Failed(e)) if e.is_refusal() => match e {
                WriteError::UnknownTag(_) => StatusCode::BadNodeIdUnknown,
                WriteError::ReadOnly(_) => StatusCode::BadNotWritable,
                WriteError::OutOfLimits { .. } => StatusCode::BadOutOfRange,
                // A standby of a redundant pair commands nothing.
                WriteError::NotActive(_) => StatusCode::BadServerNotConnected,
                WriteError::BadValue { .. } => StatusCode::BadTypeMismatch,
                // A safety tag or a switching interlock (the reason is in
                // the audit trail: OPC UA carries no text).
                WriteError::Blocked(_) => StatusCode::BadRequestNotAllowed,
                // No other error is a refusal (WriteError::is_refusal).
                _ => StatusCode::BadDeviceFailure,
            },
            Err(WriteRefused::Failed(e)) => {
                return Err(match e {
                    WriteError::Timeout(_) => StatusCode::BadTimeout,
                    WriteError::Closed => StatusCode::BadResourceUnavailable,
                    _ => StatusCode::BadDeviceFailure,
                })
            }
        };
        Ok(refused)
    }
}
